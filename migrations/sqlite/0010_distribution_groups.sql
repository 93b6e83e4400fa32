-- Each distribution row keeps the groups' accumulators it was summarised from (gzipped JSON, every
-- float by its bits), so that any quantile and any threshold can be asked after the run with the
-- summaries' intervals. Counted in the job's stored_bytes. Rows stored before have none.
ALTER TABLE distributions ADD COLUMN groups BLOB;

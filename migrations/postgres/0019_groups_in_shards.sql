-- A distribution row whose groups' accumulators are not in its own `groups` but in its job's
-- shards, as each group's shard stored them (batch 0): a job of one batch, sharded, keeps them
-- there rather than write them twice, and a query after the run reads them from there.
ALTER TABLE distributions ADD COLUMN groups_in_shards BOOLEAN NOT NULL DEFAULT FALSE;

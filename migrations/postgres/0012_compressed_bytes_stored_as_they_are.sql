-- The accumulators in shards.partial and distributions.groups are LZ4-compressed by the service
-- (store::encode), so PostgreSQL's TOAST cannot shrink them; by default it tried pglz on each
-- value over 2 kB all the same, in the writing backend. For a job of 1e7 operations (32 groups of
-- about 78 kB, 115 distribution rows of 22 kB) that was a third of PostgreSQL's CPU time: a
-- group's store took 4.9-5.6 ms instead of 3.4-3.6, the merge 146-180 ms instead of 120-141.
-- EXTERNAL keeps a large value out of line, as before, without the attempt to compress it.
ALTER TABLE shards ALTER COLUMN partial SET STORAGE EXTERNAL;
ALTER TABLE distributions ALTER COLUMN groups SET STORAGE EXTERNAL;

-- A claim takes the open job with the least virtual start time and its first claimable shard.
-- With these two indexes it walks the open jobs in that order and each one's open shards in
-- order, and stops at the first it may claim: about 0.2 ms whatever the queue holds, where
-- sorting every open shard of every open job took 36 ms per claim with 1000 jobs queued
-- (33 000 shards).
CREATE INDEX jobs_open_by_vtime ON jobs (vtime, seq) WHERE status IN ('queued', 'running');
CREATE INDEX shards_open_by_job ON shards (job_id, batch, grp) WHERE status <> 'done';

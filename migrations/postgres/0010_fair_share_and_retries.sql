-- Fair share (start-time fair queuing): vtime is a job's virtual start time, the cost of the
-- shards claimed for it (operations, plus a shard's own overhead) from where it joined: the
-- latest start time served then (the greatest vstart). vstart is the start time of its latest
-- claimed shard. A free worker claims for the job with the least vtime.
ALTER TABLE jobs ADD COLUMN vtime BIGINT NOT NULL DEFAULT 0;
ALTER TABLE jobs ADD COLUMN vstart BIGINT;
CREATE INDEX jobs_by_vstart ON jobs (vstart);
-- Retries: leases lost (a worker killed or stalled, the database out of reach) count apart from
-- runs that failed, each against its own budget; a failed run is claimed again only from
-- retry_at (exponential backoff); history keeps one line per attempt that did not finish.
ALTER TABLE shards ADD COLUMN lost_leases BIGINT NOT NULL DEFAULT 0;
ALTER TABLE shards ADD COLUMN retry_at BIGINT;
ALTER TABLE shards ADD COLUMN history TEXT NOT NULL DEFAULT '';

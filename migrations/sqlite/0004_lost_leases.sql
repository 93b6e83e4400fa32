-- How often a job's lease expired under a worker that stopped or stalled: past the configured
-- retries, the job fails with the reason instead of being run again forever.
ALTER TABLE jobs ADD COLUMN lost_leases INTEGER NOT NULL DEFAULT 0;

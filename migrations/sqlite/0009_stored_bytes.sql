-- Bytes stored for each job (the job resource's `stored_bytes`): its spec, its groups'
-- accumulators while it runs, and once it succeeded its Result, its distributions' summaries and
-- 24 bytes per listed device life (rows.rs `LIFE_ROW_BYTES`). Jobs stored before are counted once here.
ALTER TABLE jobs ADD COLUMN stored_bytes INTEGER NOT NULL DEFAULT 0;
UPDATE jobs SET stored_bytes =
    LENGTH(CAST(spec AS BLOB))
    + COALESCE((SELECT LENGTH(CAST(result AS BLOB)) FROM results WHERE job_id = jobs.id), 0)
    + COALESCE((SELECT SUM(LENGTH(CAST(summary AS BLOB))) FROM distributions WHERE job_id = jobs.id), 0)
    + 24 * (SELECT COUNT(*) FROM device_lives WHERE job_id = jobs.id)
    + COALESCE((SELECT SUM(LENGTH(partial)) FROM shards WHERE job_id = jobs.id), 0);

-- Each key's share of the queue is counted on every submission.
CREATE INDEX jobs_by_owner_status ON jobs (owner, status);

-- Finished jobs by when they ended, for retention (migrations/sqlite/0007).
CREATE INDEX jobs_finished ON jobs (finished_at) WHERE finished_at IS NOT NULL;

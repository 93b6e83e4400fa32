-- Finished jobs by when they ended: retention (`--retain-days`) deletes those that ended before a
-- time without reading the others.
CREATE INDEX jobs_finished ON jobs (finished_at) WHERE finished_at IS NOT NULL;

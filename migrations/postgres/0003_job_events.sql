-- Every change to a job is announced on the channel `bouncewear_jobs`, so that idle workers and
-- progress streams on any machine wake at once instead of polling: the payload is `queued` when a
-- job enters the queue, and the job's id for any other change (progress, status).
CREATE FUNCTION bouncewear_announce_job() RETURNS trigger AS $$
BEGIN
    IF NEW.status = 'queued' THEN
        PERFORM pg_notify('bouncewear_jobs', 'queued');
    END IF;
    PERFORM pg_notify('bouncewear_jobs', NEW.id);
    RETURN NULL;
END;
$$ LANGUAGE plpgsql;

CREATE TRIGGER jobs_announce AFTER INSERT OR UPDATE ON jobs
    FOR EACH ROW EXECUTE FUNCTION bouncewear_announce_job();

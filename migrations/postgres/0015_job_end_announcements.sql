-- A job's end is announced apart as well, as `ended <id>`, besides its id (0003): a request waiting
-- for a job's end read the job again at every announcement of it, about 60 times for the 33 claims
-- and stores of a 10^7-operation job, where only the end answers it. A build from before this
-- migration takes the new payload for the id of no job and lets it pass.
CREATE OR REPLACE FUNCTION bouncewear_announce_job() RETURNS trigger AS $$
BEGIN
    IF NEW.status = 'queued' THEN
        PERFORM pg_notify('bouncewear_jobs', 'queued');
    END IF;
    PERFORM pg_notify('bouncewear_jobs', NEW.id);
    IF NEW.status IN ('succeeded', 'failed', 'cancelled')
       AND (TG_OP = 'INSERT' OR OLD.status IS DISTINCT FROM NEW.status) THEN
        PERFORM pg_notify('bouncewear_jobs', 'ended ' || NEW.id);
    END IF;
    RETURN NULL;
END;
$$ LANGUAGE plpgsql;

-- A job runs as shards: the device groups of each batch, each run by any worker under its own lease,
-- and one merge step per batch (grp = -1) that is claimable once the batch's groups are done. The
-- lease, fencing attempt and retry count move from the job to its shards; a job is `running` from
-- its first claimed shard until its merge step stores the Result. Shards of jobs queued or running
-- before this migration are made when the store opens (service/src/store/postgres.rs).
CREATE TABLE shards (
    job_id           TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    batch            BIGINT  NOT NULL,
    grp              BIGINT  NOT NULL,                    -- group within the batch; -1: the batch's merge step
    status           TEXT    NOT NULL CHECK (status IN ('queued', 'running', 'done')),
    attempt          BIGINT  NOT NULL DEFAULT 0,          -- fencing token: bumped at every claim
    failures         BIGINT  NOT NULL DEFAULT 0,          -- runs that failed or lost their lease
    lease_owner      TEXT,
    lease_until      BIGINT,
    operations_done  BIGINT  NOT NULL DEFAULT 0,
    operations_total BIGINT  NOT NULL,
    partial          BYTEA,   -- a done group's accumulators (gzipped JSON, floats by their bits), until the Result is stored
    error            TEXT,                                -- why its last run failed
    PRIMARY KEY (job_id, batch, grp)
);
CREATE INDEX shards_open ON shards (status) WHERE status <> 'done';

ALTER TABLE jobs DROP COLUMN attempt;
ALTER TABLE jobs DROP COLUMN lease_owner;
ALTER TABLE jobs DROP COLUMN lease_until;
ALTER TABLE jobs DROP COLUMN lost_leases;

-- A shard that enters the queue (a new batch, or one handed back) wakes idle workers anywhere, as a
-- queued job does (0003).
CREATE FUNCTION bouncewear_announce_shard() RETURNS trigger AS $$
BEGIN
    IF NEW.status = 'queued' THEN
        PERFORM pg_notify('bouncewear_jobs', 'queued');
    END IF;
    RETURN NULL;
END;
$$ LANGUAGE plpgsql;

CREATE TRIGGER shards_announce AFTER INSERT OR UPDATE OF status ON shards
    FOR EACH ROW EXECUTE FUNCTION bouncewear_announce_shard();

-- A job runs as shards: the device groups of each batch, each run by any worker under its own lease,
-- and one merge step per batch (grp = -1) that is claimable once the batch's groups are done. The
-- lease, fencing attempt and retry count move from the job to its shards; a job is `running` from
-- its first claimed shard until its merge step stores the Result. Shards of jobs queued or running
-- before this migration are made when the store opens (service/src/store/sqlite.rs).
CREATE TABLE shards (
    job_id           TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    batch            INTEGER NOT NULL,
    grp              INTEGER NOT NULL,                    -- group within the batch; -1: the batch's merge step
    status           TEXT    NOT NULL CHECK (status IN ('queued', 'running', 'done')),
    attempt          INTEGER NOT NULL DEFAULT 0,          -- fencing token: bumped at every claim
    failures         INTEGER NOT NULL DEFAULT 0,          -- runs that failed or lost their lease
    lease_owner      TEXT,
    lease_until      INTEGER,
    operations_done  INTEGER NOT NULL DEFAULT 0,
    operations_total INTEGER NOT NULL,
    partial          BLOB,    -- a done group's accumulators (gzipped JSON, floats by their bits), until the Result is stored
    error            TEXT,                                -- why its last run failed
    PRIMARY KEY (job_id, batch, grp)
);
CREATE INDEX shards_open ON shards (status) WHERE status <> 'done';

ALTER TABLE jobs DROP COLUMN attempt;
ALTER TABLE jobs DROP COLUMN lease_owner;
ALTER TABLE jobs DROP COLUMN lease_until;
ALTER TABLE jobs DROP COLUMN lost_leases;

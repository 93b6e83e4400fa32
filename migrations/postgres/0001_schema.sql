-- The schema of migrations/sqlite/ 0001 to 0003 in PostgreSQL's terms: the same tables, columns and
-- keys, so that one row mapping (service/src/store/rows.rs) reads both. Times are Unix milliseconds;
-- a seed is the u64's bits as BIGINT.
CREATE TABLE jobs (
    seq              BIGINT  GENERATED ALWAYS AS IDENTITY PRIMARY KEY,  -- submission order, the paging cursor
    id               TEXT    NOT NULL UNIQUE,
    owner            TEXT    NOT NULL,                   -- SHA-256 of the API key ('' without keys)
    name             TEXT,
    spec             TEXT    NOT NULL,                   -- the job as validated, seed fixed (JSON)
    seed             BIGINT  NOT NULL,
    status           TEXT    NOT NULL CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    operations_done  BIGINT  NOT NULL DEFAULT 0,
    operations_total BIGINT  NOT NULL,
    attempt          BIGINT  NOT NULL DEFAULT 0,         -- fencing token: bumped at every claim
    lease_owner      TEXT,
    lease_until      BIGINT,
    error            TEXT,
    created_at       BIGINT  NOT NULL,
    started_at       BIGINT,
    finished_at      BIGINT
);
CREATE INDEX jobs_by_status ON jobs (status, seq);
CREATE INDEX jobs_by_owner ON jobs (owner, seq);

CREATE TABLE results (
    job_id TEXT PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    result TEXT NOT NULL                                  -- the Result JSON of docs/contract.md
);

-- One row per (job, metric, bin): queryable by SQL as well as over REST.
CREATE TABLE distributions (
    job_id     TEXT             NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    metric     TEXT             NOT NULL,
    kind       TEXT             NOT NULL CHECK (kind IN ('operation', 'device')),
    bin        BIGINT           NOT NULL,               -- 0 for device metrics
    op_start   BIGINT           NOT NULL,
    op_end     BIGINT           NOT NULL,
    n          BIGINT           NOT NULL,
    mean       DOUBLE PRECISION NOT NULL,
    sd         DOUBLE PRECISION NOT NULL,
    min        DOUBLE PRECISION NOT NULL,
    max        DOUBLE PRECISION NOT NULL,
    p05        DOUBLE PRECISION NOT NULL,
    p50        DOUBLE PRECISION NOT NULL,
    p95        DOUBLE PRECISION NOT NULL,
    exceedance DOUBLE PRECISION,                        -- probability above the job's limit, if any
    summary    TEXT             NOT NULL,               -- the full SUMMARY JSON
    PRIMARY KEY (job_id, metric, bin)
);

-- Each device's life in a job with failure criteria (the CSV of /v1/jobs/{id}/life).
CREATE TABLE device_lives (
    job_id                TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    device                BIGINT  NOT NULL,
    operations_to_failure BIGINT  NOT NULL,
    censored              BOOLEAN NOT NULL,
    PRIMARY KEY (job_id, device)
);

-- Nightly (or any cron) runs of a job template, in a time zone.
CREATE TABLE schedules (
    seq         BIGINT  GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    id          TEXT    NOT NULL UNIQUE,
    owner       TEXT    NOT NULL,
    name        TEXT    NOT NULL,
    cron        TEXT    NOT NULL,
    time_zone   TEXT    NOT NULL,
    template    TEXT    NOT NULL,           -- the job (JSON), validated
    statistics  TEXT    NOT NULL,           -- JSON list of the statistics the trend follows
    enabled     BOOLEAN NOT NULL,
    next_run_at BIGINT,                     -- the next due time, Unix ms (NULL when disabled)
    created_at  BIGINT  NOT NULL,
    updated_at  BIGINT  NOT NULL
);
CREATE INDEX schedules_due ON schedules (enabled, next_run_at);

-- One job per (schedule, due time): the primary key keeps restarts and several instances from ever
-- running a night twice. The job is inserted in the same transaction, after the run row claimed
-- the slot, hence the deferred foreign key.
CREATE TABLE schedule_runs (
    schedule_id   TEXT    NOT NULL REFERENCES schedules (id) ON DELETE CASCADE,
    scheduled_for BIGINT  NOT NULL,
    job_id        TEXT    NOT NULL REFERENCES jobs (id) DEFERRABLE INITIALLY DEFERRED,
    manual        BOOLEAN NOT NULL DEFAULT FALSE,
    PRIMARY KEY (schedule_id, scheduled_for)
);

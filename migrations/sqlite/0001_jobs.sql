-- Jobs, their queue state, results and distributions. Times are Unix milliseconds.
CREATE TABLE jobs (
    seq              INTEGER PRIMARY KEY AUTOINCREMENT,  -- submission order, the paging cursor
    id               TEXT    NOT NULL UNIQUE,
    owner            TEXT    NOT NULL,                   -- SHA-256 of the API key ('' without keys)
    name             TEXT,
    spec             TEXT    NOT NULL,                   -- the job as validated, seed fixed (JSON)
    status           TEXT    NOT NULL CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    operations_done  INTEGER NOT NULL DEFAULT 0,
    operations_total INTEGER NOT NULL,
    attempt          INTEGER NOT NULL DEFAULT 0,         -- fencing token: bumped at every claim
    lease_owner      TEXT,
    lease_until      INTEGER,
    error            TEXT,
    created_at       INTEGER NOT NULL,
    started_at       INTEGER,
    finished_at      INTEGER
);
CREATE INDEX jobs_by_status ON jobs (status, seq);
CREATE INDEX jobs_by_owner ON jobs (owner, seq);

CREATE TABLE results (
    job_id TEXT PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    result TEXT NOT NULL                                  -- the Result JSON of CONTRACT.md
);

-- One row per (job, metric, bin): queryable by SQL as well as over REST.
CREATE TABLE distributions (
    job_id     TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    metric     TEXT    NOT NULL,
    kind       TEXT    NOT NULL CHECK (kind IN ('operation', 'device')),
    bin        INTEGER NOT NULL,                          -- 0 for device metrics
    op_start   INTEGER NOT NULL,
    op_end     INTEGER NOT NULL,
    n          INTEGER NOT NULL,
    mean       REAL    NOT NULL,
    sd         REAL    NOT NULL,
    min        REAL    NOT NULL,
    max        REAL    NOT NULL,
    p05        REAL    NOT NULL,
    p50        REAL    NOT NULL,
    p95        REAL    NOT NULL,
    exceedance REAL,                                      -- probability above the job's limit, if any
    summary    TEXT    NOT NULL,                          -- the full SUMMARY JSON
    PRIMARY KEY (job_id, metric, bin)
);

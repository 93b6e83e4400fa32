-- Each device's life in a job with failure criteria (the CSV of /v1/jobs/{id}/life).
CREATE TABLE device_lives (
    job_id                TEXT    NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    device                INTEGER NOT NULL,
    operations_to_failure INTEGER NOT NULL,
    censored              INTEGER NOT NULL,
    PRIMARY KEY (job_id, device)
);

-- Nightly (or any cron) runs of a job template, in a time zone.
CREATE TABLE schedules (
    seq         INTEGER PRIMARY KEY AUTOINCREMENT,
    id          TEXT    NOT NULL UNIQUE,
    owner       TEXT    NOT NULL,
    name        TEXT    NOT NULL,
    cron        TEXT    NOT NULL,
    time_zone   TEXT    NOT NULL,
    template    TEXT    NOT NULL,           -- the job (JSON), validated
    statistics  TEXT    NOT NULL,           -- JSON list of the statistics the trend follows
    enabled     INTEGER NOT NULL,
    next_run_at INTEGER,                    -- the next due time, Unix ms (NULL when disabled)
    created_at  INTEGER NOT NULL,
    updated_at  INTEGER NOT NULL
);
CREATE INDEX schedules_due ON schedules (enabled, next_run_at);

-- One job per (schedule, due time): the primary key is what keeps restarts and several instances
-- from ever running a night twice. The job is inserted in the same transaction, after the run row
-- claimed the slot, hence the deferred foreign key.
CREATE TABLE schedule_runs (
    schedule_id   TEXT    NOT NULL REFERENCES schedules (id) ON DELETE CASCADE,
    scheduled_for INTEGER NOT NULL,
    job_id        TEXT    NOT NULL REFERENCES jobs (id) DEFERRABLE INITIALLY DEFERRED,
    manual        INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (schedule_id, scheduled_for)
);

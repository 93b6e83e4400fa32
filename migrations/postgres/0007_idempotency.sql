-- What a POST with an `Idempotency-Key` header created (migrations/sqlite/0008).
CREATE TABLE idempotency_keys (
    owner       TEXT    NOT NULL,
    collection  TEXT    NOT NULL CHECK (collection IN ('jobs', 'schedules')),
    key         TEXT    NOT NULL,
    fingerprint TEXT    NOT NULL,                        -- SHA-256 (hex) of the request body
    job_id      TEXT    REFERENCES jobs (id) ON DELETE CASCADE,
    schedule_id TEXT    REFERENCES schedules (id) ON DELETE CASCADE,
    created_at  BIGINT  NOT NULL,
    PRIMARY KEY (owner, collection, key)
);

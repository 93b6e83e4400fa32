-- What a POST with an `Idempotency-Key` header created, so that its retry (same owner, collection,
-- key and body, within 24 hours) gets that resource again instead of a second one. A row goes with
-- its resource.
CREATE TABLE idempotency_keys (
    owner       TEXT    NOT NULL,
    collection  TEXT    NOT NULL CHECK (collection IN ('jobs', 'schedules')),
    key         TEXT    NOT NULL,
    fingerprint TEXT    NOT NULL,                        -- SHA-256 (hex) of the request body
    job_id      TEXT    REFERENCES jobs (id) ON DELETE CASCADE,
    schedule_id TEXT    REFERENCES schedules (id) ON DELETE CASCADE,
    created_at  INTEGER NOT NULL,
    PRIMARY KEY (owner, collection, key)
);

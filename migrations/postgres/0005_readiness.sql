-- The one row `/readyz` writes, so that readiness shows the database takes a write
-- (migrations/sqlite/0006).
CREATE TABLE readiness (
    id         BIGINT PRIMARY KEY CHECK (id = 1),
    checked_at BIGINT NOT NULL                          -- Unix ms of the last readiness check
);

-- The one row `/readyz` writes: readiness must show that the database takes a write that reaches
-- the disk, which neither a read nor a rolled-back write would (in WAL mode a write is only written
-- out at commit).
CREATE TABLE readiness (
    id         INTEGER PRIMARY KEY CHECK (id = 1),
    checked_at INTEGER NOT NULL                         -- Unix ms of the last readiness check
);

-- A secret drawn once per database, which every instance on it reads at start-up: listing cursors
-- are sealed with it, so that a cursor names a place in the list without showing the row's
-- sequence number (whose gaps would count the jobs and schedules of other keys).
CREATE TABLE secrets (
    name  TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
INSERT INTO secrets (name, value)
VALUES ('cursor', replace(gen_random_uuid()::text || gen_random_uuid()::text, '-', ''));

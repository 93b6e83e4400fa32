-- The runs a schedule skipped (its template refused by the server's limits now, its key over its
-- quota): how many, and the latest one's due time and why, so that a lost night shows on the
-- schedule and not only in the server's log.
ALTER TABLE schedules ADD COLUMN skipped_runs INTEGER NOT NULL DEFAULT 0;
ALTER TABLE schedules ADD COLUMN last_skipped_for INTEGER;  -- Unix ms
ALTER TABLE schedules ADD COLUMN last_skip_reason TEXT;

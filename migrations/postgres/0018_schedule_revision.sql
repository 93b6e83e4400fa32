-- How often each schedule was replaced (a PUT adds one): a scheduled run is made, and its
-- schedule's next run moved, only if the schedule is still the one the scheduler read, so that no
-- run comes of a definition replaced or disabled meanwhile.
ALTER TABLE schedules ADD COLUMN revision BIGINT NOT NULL DEFAULT 0;

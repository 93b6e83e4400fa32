-- The seed a job runs with, so that rendering a job never parses its stored spec. It holds the u64
-- seed's bits as SQLite's signed 64-bit integer (a seed of 2^63 or more reads as negative in SQL).
-- Jobs stored before this column get it from their spec when the store opens (exact for every u64,
-- which SQLite's JSON functions are not).
ALTER TABLE jobs ADD COLUMN seed INTEGER;

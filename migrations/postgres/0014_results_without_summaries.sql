-- From this migration on, results.result holds the Result JSON with `operations` and `devices`
-- empty: each summary is stored once, in its distributions row, and the store puts them back when
-- the Result is read. Results stored before stay whole and read as they were. The schema does not
-- change: the migration marks the database, so that a build from before it refuses to start on it
-- (an applied migration it does not know) rather than serve Results without their summaries.
COMMENT ON COLUMN results.result IS
    'The Result JSON; since migration 14 without its summaries (operations and devices empty), '
    'which its distributions rows hold';

-- Tiled jobs: a job with "partition" is a parent row with `tiles` set and
-- one child row per tile (`parent_id`); workers run the children, then
-- the parent (the merge) once every child is final.
ALTER TABLE jobs ADD COLUMN parent_id INTEGER;
ALTER TABLE jobs ADD COLUMN tiles INTEGER;
CREATE INDEX IF NOT EXISTS jobs_parent ON jobs (parent_id);

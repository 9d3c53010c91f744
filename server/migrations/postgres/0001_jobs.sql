-- The job table shared by every API and worker process. Ids are
-- allocated from meta's next_id (never reused); uid is the public id.
CREATE TABLE IF NOT EXISTS jobs (
    id BIGINT PRIMARY KEY,
    uid TEXT NOT NULL UNIQUE,
    tenant TEXT,
    state TEXT NOT NULL,
    stage TEXT,
    error TEXT,
    summary TEXT,
    bake BIGINT NOT NULL,
    scene_kind TEXT NOT NULL,
    created_ms BIGINT NOT NULL,
    started_ms BIGINT,
    finished_ms BIGINT,
    -- Leases: a worker claims a job by taking its lease, renews it while
    -- it runs and writes the final state only while it still holds it; a
    -- job whose lease ran out is claimed again.
    progress DOUBLE PRECISION,
    lease_owner TEXT,
    lease_until_ms BIGINT,
    attempts BIGINT NOT NULL DEFAULT 0,
    completions BIGINT NOT NULL DEFAULT 0,
    cancel_requested BIGINT NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs (tenant, id);
CREATE INDEX IF NOT EXISTS jobs_queue ON jobs (state, id);
CREATE TABLE IF NOT EXISTS meta (k TEXT PRIMARY KEY, v BIGINT NOT NULL);
INSERT INTO meta (k, v) VALUES ('next_id', 1) ON CONFLICT (k) DO NOTHING;
CREATE TABLE IF NOT EXISTS workers (
    id TEXT PRIMARY KEY,
    started_ms BIGINT NOT NULL,
    seen_ms BIGINT NOT NULL
);

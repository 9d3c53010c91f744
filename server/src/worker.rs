//! The worker threads: each claims the oldest queued job from the database
//! under a lease (see [`crate::store::Store::claim`]) and runs it off the
//! async runtime, publishing its live stage and progress, renewing the
//! lease and watching its cancel flag. The same loop runs in the
//! single-process server and in `impostor-server worker` processes.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc};
use std::time::Duration;

use crate::AppState;
use crate::job::{CANCELLED_BY_REQUEST, JobState};
use crate::pipeline::{RunOptions, merge_job, run_job, run_tile};
use crate::store::Run;

/// Wakes idle workers of this process when a job is submitted here; they
/// also look at the database every [`POLL`] for jobs submitted elsewhere
/// (other API processes) or leases that ran out.
#[derive(Default)]
pub(crate) struct Wakeup {
    submitted: Mutex<u64>,
    cv: Condvar,
}

/// How often an idle worker looks for a job.
pub(crate) const POLL: Duration = Duration::from_millis(500);

/// How often an idle worker records that it is alive (`/metrics` counts
/// the workers seen in the last minute).
const SEEN_EVERY: Duration = Duration::from_secs(10);

impl Wakeup {
    /// A job was submitted.
    pub fn notify(&self) {
        if let Ok(mut n) = self.submitted.lock() {
            *n += 1;
        }
        self.cv.notify_all();
    }

    /// Waits until a job is submitted after `seen` submissions, or `POLL`.
    fn wait(&self, seen: u64) -> u64 {
        let Ok(n) = self.submitted.lock() else {
            return seen;
        };
        match self.cv.wait_timeout_while(n, POLL, |n| *n == seen) {
            Ok((n, _)) => *n,
            Err(_) => seen,
        }
    }

    fn count(&self) -> u64 {
        self.submitted.lock().map_or(0, |n| *n)
    }
}

/// Live progress of a running job.
struct Live {
    stage: String,
    progress: f64,
    stop: Arc<Stop>,
}

/// Why a running job was asked to stop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stopped {
    /// It was not.
    No = 0,
    /// A `DELETE` cancelled it.
    ByRequest = 1,
    /// It ran past the server's `--job-max-seconds`.
    TimeLimit = 2,
    /// Its worker lost the lease (it could not renew it in time, and
    /// another worker may have taken the job over): its end is not recorded.
    LeaseLost = 3,
    /// Its worker is shutting down: the lease is given back and the job
    /// queued again.
    Shutdown = 4,
}

/// Asks a running job to stop: the flag the optimizer checks, and the
/// reason first given (a cancel and a time limit may race: the first wins).
#[derive(Default)]
pub(crate) struct Stop {
    cancel: AtomicBool,
    reason: AtomicU8,
}

impl Stop {
    fn ask(&self, why: Stopped) {
        let _ = self.reason.compare_exchange(
            Stopped::No as u8,
            why as u8,
            Ordering::SeqCst,
            Ordering::SeqCst,
        );
        self.cancel.store(true, Ordering::SeqCst);
    }

    fn reason(&self) -> Stopped {
        match self.reason.load(Ordering::SeqCst) {
            1 => Stopped::ByRequest,
            2 => Stopped::TimeLimit,
            3 => Stopped::LeaseLost,
            4 => Stopped::Shutdown,
            _ => Stopped::No,
        }
    }
}

/// The running jobs' live stage, progress and cancel flag. A job is here
/// while a worker runs it through the optimizer.
#[derive(Default)]
pub(crate) struct LiveJobs(Mutex<HashMap<i64, Live>>);

impl LiveJobs {
    /// The stage and progress of job `id`, if it is running.
    pub fn progress(&self, id: i64) -> Option<(String, f64)> {
        let live = self.0.lock().ok()?;
        live.get(&id).map(|l| (l.stage.clone(), l.progress))
    }

    /// Asks running job `id` to stop; it ends `cancelled` at its next check.
    pub fn cancel(&self, id: i64) {
        if let Ok(live) = self.0.lock()
            && let Some(l) = live.get(&id)
        {
            l.stop.ask(Stopped::ByRequest);
        }
    }

    fn start(&self, id: i64) -> Arc<Stop> {
        let stop = Arc::new(Stop::default());
        if let Ok(mut live) = self.0.lock() {
            live.insert(
                id,
                Live {
                    stage: "loading".into(),
                    progress: 0.0,
                    stop: stop.clone(),
                },
            );
        }
        stop
    }

    fn update(&self, id: i64, stage: &str, progress: f64) {
        if let Ok(mut live) = self.0.lock()
            && let Some(l) = live.get_mut(&id)
        {
            if l.stage != stage {
                tracing::info!(job = id, stage, "stage");
            }
            l.stage = stage.to_string();
            l.progress = progress;
        }
    }

    fn finish(&self, id: i64) {
        if let Ok(mut live) = self.0.lock() {
            live.remove(&id);
        }
    }

    /// Asks every running job to stop for `why`.
    fn stop_all(&self, why: Stopped) {
        if let Ok(live) = self.0.lock() {
            for l in live.values() {
                l.stop.ask(why);
            }
        }
    }
}

/// This process's worker name: host, process id and a random suffix
/// (a process restarted with the same id is another worker).
pub(crate) fn process_name() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "host".into());
    let tag = uuid::Uuid::new_v4().simple().to_string();
    format!("{host}:{}:{}", std::process::id(), &tag[..8])
}

/// Starts `count` worker threads that claim jobs from the database until
/// [`AppState::shutdown`]; returns their handles.
pub(crate) fn spawn_workers(
    state: &AppState,
    count: usize,
) -> std::io::Result<Vec<std::thread::JoinHandle<()>>> {
    (0..count)
        .map(|w| {
            let st = state.clone();
            let owner = format!("{}/{w}", st.0.name);
            std::thread::Builder::new()
                .name(format!("worker-{w}"))
                .spawn(move || work(&st, &owner))
        })
        .collect()
}

/// One worker's loop: claim the oldest job, run it, repeat; wait for a
/// submission (or the next poll) when there is none.
fn work(st: &AppState, owner: &str) {
    let store = &st.0.store;
    let wakeup = &st.0.wakeup;
    let lease_ms = st.0.cfg.lease.as_millis() as i64;
    let mut seen = wakeup.count();
    // An idle worker says it is alive every SEEN_EVERY, not at every poll.
    let mut said: Option<std::time::Instant> = None;
    while !st.0.stopping.load(Ordering::SeqCst) {
        if said.is_none_or(|t| t.elapsed() >= SEEN_EVERY) {
            match store.worker_seen(owner) {
                Ok(()) => said = Some(std::time::Instant::now()),
                Err(e) => tracing::warn!(worker = owner, "database: {e}"),
            }
        }
        match store.claim(owner, lease_ms) {
            Ok(Some(c)) => run(st, owner, c.id, c.bake, c.run),
            Ok(None) => seen = wakeup.wait(seen),
            Err(e) => {
                tracing::warn!(worker = owner, "cannot claim a job: {e}");
                std::thread::sleep(POLL);
            }
        }
    }
    let _ = store.worker_gone(owner);
}

/// Renews the lease of job `id` every third of the lease until `ended`
/// says the run is over, recording its live stage and progress; asks the
/// run to stop when a `DELETE` asked for it or the lease was lost.
fn keep_lease(st: &AppState, owner: &str, id: i64, stop: &Stop, ended: &mpsc::Receiver<()>) {
    let every = st.0.cfg.lease / 3;
    let lease_ms = st.0.cfg.lease.as_millis() as i64;
    while ended.recv_timeout(every) == Err(mpsc::RecvTimeoutError::Timeout) {
        let (stage, progress) =
            st.0.live
                .progress(id)
                .unwrap_or_else(|| ("loading".into(), 0.0));
        match st.0.store.renew(id, owner, lease_ms, &stage, progress) {
            Ok(r) if !r.held => {
                tracing::warn!(job = id, worker = owner, "lease lost");
                stop.ask(Stopped::LeaseLost);
                return;
            }
            Ok(r) => {
                if r.cancel {
                    stop.ask(Stopped::ByRequest);
                }
                let _ = st.0.store.worker_seen(owner);
            }
            // The lease runs out unless a later renewal gets through.
            Err(e) => tracing::warn!(job = id, "cannot renew the lease: {e}"),
        }
    }
}

/// Runs job `id`, claimed by `owner`, on the calling (worker) thread and
/// records its final state while `owner` still holds its lease.
fn run(st: &AppState, owner: &str, id: i64, bake: bool, kind: Run) {
    let store = &st.0.store;
    let live = &st.0.live;
    let stop = live.start(id);
    tracing::info!(job = id, worker = owner, "running");
    let progress = |stage: &str, f: f64| live.update(id, stage, f);
    let opts = RunOptions {
        bake,
        eval_views: st.0.cfg.eval_views,
        cancel: &stop.cancel,
        max_memory_bytes: st.0.cfg.job_max_memory_bytes,
        progress: &progress,
    };
    let files = store.files(id);
    // The time limit: a watchdog asks the job to stop unless it ends first.
    let (ended, watch) = mpsc::channel::<()>();
    let limit = st.0.cfg.job_max_seconds;
    let watchdog = limit.and_then(|secs| {
        let stop = stop.clone();
        std::thread::Builder::new()
            .name(format!("job-{id}-limit"))
            .spawn(move || {
                if watch.recv_timeout(Duration::from_secs(secs))
                    == Err(mpsc::RecvTimeoutError::Timeout)
                {
                    stop.ask(Stopped::TimeLimit);
                }
            })
            .inspect_err(|e| tracing::warn!(job = id, "no time limit: {e}"))
            .ok()
    });
    let (lease_end, lease_watch) = mpsc::channel::<()>();
    let outcome = std::thread::scope(|s| {
        let stop = &stop;
        let keeper = s.spawn(move || keep_lease(st, owner, id, stop, &lease_watch));
        // A panic in the optimizer fails this job, not the worker.
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match kind {
            Run::Whole => run_job(files, &opts),
            Run::Tile => run_tile(files, &opts),
            Run::Merge => merge_tiles(store, id, &opts),
        }));
        drop(lease_end);
        let _ = keeper.join();
        outcome
    });
    let stopped = stop.reason();
    drop(ended);
    if let Some(w) = watchdog {
        let _ = w.join();
    }
    live.finish(id);
    match stopped {
        Stopped::LeaseLost => {
            tracing::warn!(job = id, "run discarded: the lease was lost");
        }
        Stopped::Shutdown => match store.release(id, owner) {
            Ok(_) => tracing::info!(job = id, "lease released: queued again"),
            Err(e) => tracing::warn!(job = id, "cannot release the lease (it runs out): {e}"),
        },
        _ => {
            let (state, error, summary) = final_state(outcome, stopped, limit.unwrap_or(0));
            match store.finish(id, owner, state, error.as_deref(), summary.as_deref()) {
                Ok(true) => match state {
                    JobState::Succeeded => tracing::info!(job = id, "succeeded"),
                    JobState::Cancelled => tracing::info!(job = id, "cancelled"),
                    _ => tracing::warn!(job = id, "failed: {}", error.as_deref().unwrap_or("")),
                },
                Ok(false) => tracing::warn!(job = id, "run discarded: the lease was lost"),
                Err(e) => tracing::error!(job = id, "database update failed: {e}"),
            }
        }
    }
    optimizer::place::release_memory();
}

/// The merge of tiled job `id` once its tiles are final: fails naming the
/// first tile that did not succeed.
fn merge_tiles(
    store: &crate::store::Store,
    id: i64,
    opts: &RunOptions<'_>,
) -> optimizer::Result<String> {
    let tiles = store
        .children(id)
        .map_err(|e| optimizer::Error::Internal(format!("the tiles of job {id}: {e}")))?;
    for (k, t) in tiles.iter().enumerate() {
        match t.state {
            JobState::Succeeded => {}
            JobState::Cancelled => return Err(optimizer::Error::Cancelled),
            _ => {
                return Err(optimizer::Error::bad(
                    format!("tile {} of {}", k + 1, tiles.len()),
                    t.error
                        .clone()
                        .unwrap_or_else(|| format!("ended {}", t.state)),
                ));
            }
        }
    }
    let parts: Vec<_> = tiles.iter().map(|t| store.files(t.id)).collect();
    merge_job(store.files(id), &parts, opts)
}

/// Stops the workers of `st`: no more claims; running jobs are stopped and
/// their leases given back (queued again for any worker).
pub(crate) fn shutdown(st: &AppState) {
    st.0.stopping.store(true, Ordering::SeqCst);
    st.0.live.stop_all(Stopped::Shutdown);
    st.0.wakeup.notify();
}

/// The state a run ends in, its error and its summary: a job cancelled by
/// a request while it ran ends `cancelled` whatever its last stage did (its
/// results, if written, are removed with it by a later `DELETE`); one
/// stopped at the server's time limit (`limit_s` seconds) ends `failed`,
/// naming the limit. A failure caused by the job's input keeps the
/// optimizer's message (it names the file and field); any other (a file
/// of the server that cannot be read or written, a panic, a broken
/// invariant) is logged with a request id, which is all the job's error
/// says.
fn final_state(
    outcome: std::thread::Result<optimizer::Result<String>>,
    stopped: Stopped,
    limit_s: u64,
) -> (JobState, Option<String>, Option<String>) {
    let cancelled = || {
        (
            JobState::Cancelled,
            Some(CANCELLED_BY_REQUEST.to_string()),
            None,
        )
    };
    match outcome {
        _ if matches!(
            stopped,
            Stopped::ByRequest | Stopped::LeaseLost | Stopped::Shutdown
        ) =>
        {
            cancelled()
        }
        _ if stopped == Stopped::TimeLimit => (
            JobState::Failed,
            Some(format!(
                "stopped after {limit_s} s, the server's --job-max-seconds limit"
            )),
            None,
        ),
        Ok(Ok(summary)) => (JobState::Succeeded, None, Some(summary)),
        Ok(Err(optimizer::Error::Cancelled)) => cancelled(),
        Ok(Err(e)) if e.is_bad_input() => (JobState::Failed, Some(e.to_string()), None),
        Ok(Err(e)) => (JobState::Failed, Some(internal(&e)), None),
        Err(_) => (
            JobState::Failed,
            Some(internal(&"the optimizer panicked (a bug)")),
            None,
        ),
    }
}

/// Logs a job's internal error under a new request id; the job's error
/// names only the id.
fn internal(e: &dyn std::fmt::Display) -> String {
    let id = crate::error::new_request_id();
    tracing::error!(request_id = id, "job failed: {e}");
    format!("internal error (request {id}; the server's log has the details)")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rss_bytes() -> u64 {
        optimizer::place::current_rss_bytes()
    }

    /// Memory a job allocated in small blocks and freed is returned to the
    /// system once the job is over, not kept by the allocator.
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn freed_job_memory_is_returned() {
        // 512 MB in 32 KB blocks (below glibc's mmap threshold, so they
        // come from the heap and stay there when freed), touched.
        let blocks: Vec<Vec<u8>> = (0..16_384).map(|i| vec![i as u8; 32 << 10]).collect();
        let full = rss_bytes();
        // Keep the last block so the heap's top is in use.
        let last = blocks.into_iter().last();
        let freed = rss_bytes();
        optimizer::place::release_memory();
        let released = rss_bytes();
        drop(last);
        assert!(full > 500 << 20, "{full}");
        assert!(
            released + (400 << 20) < freed,
            "rss {full} full, {freed} freed, {released} after release"
        );
    }

    /// A cancel that arrives during a job's last stage (the bake, which does
    /// not stop part-way) wins over its success, and over its failure.
    #[test]
    fn cancellation_wins_over_the_last_stage() {
        let ok = || Ok(Ok("{}".to_string()));
        assert_eq!(final_state(ok(), Stopped::No, 0).0, JobState::Succeeded);
        let (state, error, summary) = final_state(ok(), Stopped::ByRequest, 0);
        assert_eq!(state, JobState::Cancelled);
        assert_eq!(error.as_deref(), Some(CANCELLED_BY_REQUEST));
        assert!(summary.is_none());
        let failed = || Ok(Err(optimizer::Error::bad("job", "nope")));
        assert_eq!(final_state(failed(), Stopped::No, 0).0, JobState::Failed);
        assert_eq!(
            final_state(failed(), Stopped::ByRequest, 0).0,
            JobState::Cancelled
        );
        let panicked = final_state(Err(Box::new("boom")), Stopped::No, 0);
        assert_eq!(panicked.0, JobState::Failed);
        let text = panicked.1.unwrap();
        assert!(text.starts_with("internal error (request "), "{text}");
        assert!(!text.contains("boom"), "{text}");
        // A file of the server that cannot be read is not named to the
        // client; bad input is, with its field.
        let io = optimizer::Error::io(
            "/srv/impostor-data/jobs/7/scene",
            std::io::Error::other("disk I/O error"),
        );
        let (state, error, _) = final_state(Ok(Err(io)), Stopped::No, 0);
        assert_eq!(state, JobState::Failed);
        let text = error.unwrap();
        assert!(text.starts_with("internal error (request "), "{text}");
        assert!(!text.contains("/srv") && !text.contains("disk"), "{text}");
        let (_, error, _) = final_state(failed(), Stopped::No, 0);
        assert_eq!(error.as_deref(), Some("job: nope"));
    }

    /// A job stopped at the time limit fails naming the limit, whether its
    /// run noticed the stop or finished its last stage first; the first
    /// reason to stop wins.
    #[test]
    fn a_job_past_the_time_limit_fails_naming_it() {
        for outcome in [
            Ok(Err(optimizer::Error::Cancelled)),
            Ok(Ok("{}".to_string())),
        ] {
            let (state, error, summary) = final_state(outcome, Stopped::TimeLimit, 30);
            assert_eq!(state, JobState::Failed);
            assert_eq!(
                error.as_deref(),
                Some("stopped after 30 s, the server's --job-max-seconds limit")
            );
            assert!(summary.is_none());
        }
        let stop = Stop::default();
        assert_eq!(stop.reason(), Stopped::No);
        stop.ask(Stopped::TimeLimit);
        stop.ask(Stopped::ByRequest);
        assert_eq!(stop.reason(), Stopped::TimeLimit);
        assert!(stop.cancel.load(Ordering::SeqCst));
    }
}

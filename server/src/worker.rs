//! The job queue and the worker threads: each worker takes the next queued
//! job and runs it off the async runtime, publishing its live stage and
//! progress and watching its cancel flag.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

use crate::AppState;
use crate::job::{CANCELLED_BY_REQUEST, JobState};
use crate::pipeline::{RunOptions, run_job};

/// The ids of the jobs waiting for a worker, in submission order.
pub(crate) struct Queue {
    tx: Mutex<mpsc::Sender<i64>>,
    waiting: AtomicUsize,
}

impl Queue {
    /// A queue and the receiving end its workers share.
    pub fn new() -> (Queue, mpsc::Receiver<i64>) {
        let (tx, rx) = mpsc::channel();
        let queue = Queue {
            tx: Mutex::new(tx),
            waiting: AtomicUsize::new(0),
        };
        (queue, rx)
    }

    /// Queues job `id`.
    pub fn push(&self, id: i64) {
        self.waiting.fetch_add(1, Ordering::SeqCst);
        if let Ok(tx) = self.tx.lock() {
            let _ = tx.send(id);
        }
    }

    /// Counts job ids a worker took from the receiving end.
    fn taken(&self) {
        self.waiting.fetch_sub(1, Ordering::SeqCst);
    }

    /// Jobs queued and not yet taken by a worker.
    pub fn waiting(&self) -> usize {
        self.waiting.load(Ordering::SeqCst)
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
}

/// Starts `count` worker threads (at least one) that take job ids from `rx`
/// until the queue's sending end is gone.
pub(crate) fn spawn_workers(
    state: &AppState,
    rx: mpsc::Receiver<i64>,
    count: usize,
) -> std::io::Result<()> {
    let rx = Arc::new(Mutex::new(rx));
    for w in 0..count {
        let st = state.clone();
        let rx = rx.clone();
        std::thread::Builder::new()
            .name(format!("worker-{w}"))
            .spawn(move || {
                loop {
                    let next = rx.lock().map(|r| r.recv());
                    match next {
                        Ok(Ok(id)) => {
                            st.0.queue.taken();
                            run(&st, id);
                        }
                        _ => break,
                    }
                }
            })?;
    }
    Ok(())
}

/// Runs job `id` on the calling (worker) thread and stores its final state.
/// A job no longer queued (cancelled or deleted meanwhile) is skipped.
fn run(st: &AppState, id: i64) {
    let store = &st.0.store;
    let bake = match store.row(id) {
        Ok(Some(row)) if row.state == JobState::Queued => row.bake,
        _ => return,
    };
    let live = &st.0.live;
    let stop = live.start(id);
    store.set_state(id, JobState::Running, None, None);
    tracing::info!(job = id, "running");
    let progress = |stage: &str, f: f64| live.update(id, stage, f);
    let opts = RunOptions {
        bake,
        eval_views: st.0.cfg.eval_views,
        cancel: &stop.cancel,
        max_memory_bytes: st.0.cfg.job_max_memory_bytes,
        progress: &progress,
    };
    let dir = store.job_dir(id);
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
    // A panic in the optimizer fails this job, not the worker.
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_job(&dir, &opts)));
    let stopped = stop.reason();
    drop(ended);
    if let Some(w) = watchdog {
        let _ = w.join();
    }
    live.finish(id);
    let (state, error, summary) = final_state(outcome, stopped, limit.unwrap_or(0));
    match state {
        JobState::Succeeded => tracing::info!(job = id, "succeeded"),
        JobState::Cancelled => tracing::info!(job = id, "cancelled"),
        _ => tracing::warn!(job = id, "failed: {}", error.as_deref().unwrap_or("")),
    }
    store.set_state(id, state, error.as_deref(), summary.as_deref());
    release_memory();
}

/// Gives the heap a finished job freed back to the system: glibc keeps
/// freed memory in its arenas, so after a job of several gigabytes an idle
/// server would stay that large. The one `unsafe` of the workspace: a libc
/// call with no preconditions.
#[allow(unsafe_code)]
fn release_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free heap pages to the system; it
    // has no preconditions and touches no memory in use.
    unsafe {
        libc::malloc_trim(0);
    }
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
        _ if stopped == Stopped::ByRequest => cancelled(),
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
        release_memory();
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

//! The job queue and the worker threads: each worker takes the next queued
//! job and runs it off the async runtime, publishing its live stage and
//! progress and watching its cancel flag.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, mpsc};

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
    cancel: Arc<AtomicBool>,
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
            l.cancel.store(true, Ordering::Relaxed);
        }
    }

    fn start(&self, id: i64) -> Arc<AtomicBool> {
        let cancel = Arc::new(AtomicBool::new(false));
        if let Ok(mut live) = self.0.lock() {
            live.insert(
                id,
                Live {
                    stage: "loading".into(),
                    progress: 0.0,
                    cancel: cancel.clone(),
                },
            );
        }
        cancel
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
    for w in 0..count.max(1) {
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
    let cancel = live.start(id);
    store.set_state(id, JobState::Running, None, None);
    tracing::info!(job = id, "running");
    let progress = |stage: &str, f: f64| live.update(id, stage, f);
    let opts = RunOptions {
        bake,
        eval_views: st.0.cfg.eval_views,
        cancel: &cancel,
        progress: &progress,
    };
    let dir = store.job_dir(id);
    // A panic in the optimizer fails this job, not the worker.
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_job(&dir, &opts)));
    live.finish(id);
    match outcome {
        Ok(Ok(summary)) => {
            tracing::info!(job = id, "succeeded");
            store.set_state(id, JobState::Succeeded, None, Some(&summary));
        }
        Ok(Err(optimizer::Error::Cancelled)) => {
            tracing::info!(job = id, "cancelled");
            store.set_state(id, JobState::Cancelled, Some(CANCELLED_BY_REQUEST), None);
        }
        Ok(Err(e)) => {
            tracing::warn!(job = id, "failed: {e}");
            store.set_state(id, JobState::Failed, Some(&e.to_string()), None);
        }
        Err(_) => {
            tracing::error!(job = id, "panicked");
            store.set_state(id, JobState::Failed, Some("internal error (a bug)"), None);
        }
    }
}

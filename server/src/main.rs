//! `impostor-server`: the HTTP service (see the library docs and README).

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::Parser;
use server::{AppState, Config, run};

/// HTTP service for impostor placement jobs.
#[derive(Parser)]
#[command(name = "impostor-server", version, about)]
struct Cli {
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    listen: String,
    /// Directory of the job database and files.
    #[arg(long, default_value = "impostor-data")]
    data_dir: PathBuf,
    /// Worker threads (jobs running at once).
    #[arg(long, default_value_t = 1)]
    workers: usize,
    /// Largest upload, MiB.
    #[arg(long, default_value_t = 256)]
    max_upload_mb: usize,
    /// Most jobs waiting in the queue.
    #[arg(long, default_value_t = 64)]
    max_queue: usize,
    /// The longest a job may run, seconds: it is stopped and ends `failed`
    /// (default: no limit).
    #[arg(long, value_name = "SECONDS", value_parser = clap::value_parser!(u64).range(1..))]
    job_max_seconds: Option<u64>,
    /// The most memory a job's placement may be predicted to need, GB: a
    /// job predicted to need more ends `failed` before allocating it
    /// (default: the machine's memory).
    #[arg(long, value_name = "GB", value_parser = parse_gb)]
    job_max_memory: Option<u64>,
    /// Remove finished jobs (succeeded, failed or cancelled) and their files
    /// this many days after they finished (default: keep them).
    #[arg(long, value_name = "DAYS", value_parser = parse_days)]
    retain_days: Option<f64>,
}

/// A positive number of days.
fn parse_days(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(d) if d.is_finite() && d > 0.0 && d <= 1e6 => Ok(d),
        _ => Err(format!("expected a positive number of days, got {s:?}")),
    }
}

/// A positive number of GB, as bytes.
fn parse_gb(s: &str) -> Result<u64, String> {
    match s.parse::<f64>() {
        Ok(g) if g.is_finite() && g > 0.0 && g <= 1e9 => Ok((g * 1e9) as u64),
        _ => Err(format!("expected a positive number of GB, got {s:?}")),
    }
}

#[tokio::main]
async fn main() -> std::io::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    let cli = Cli::parse();
    let mut cfg = Config::new(cli.data_dir);
    cfg.workers = cli.workers.max(1);
    cfg.max_upload_mb = cli.max_upload_mb.max(1);
    cfg.max_queue = cli.max_queue.max(1);
    cfg.job_max_seconds = cli.job_max_seconds;
    cfg.job_max_memory_bytes = cli.job_max_memory;
    cfg.retain_days = cli.retain_days;
    let state = AppState::open(cfg)?;
    let listener = tokio::net::TcpListener::bind(&cli.listen).await?;
    tracing::info!("listening on {}", listener.local_addr()?);
    run(listener, state, shutdown_signal()).await
}

/// Completes on Ctrl-C (SIGINT) or SIGTERM, what service managers and
/// container runtimes send: the server stops accepting connections, answers
/// those in flight and exits 0; a job still running is queued again when the
/// server next starts on the same data folder.
async fn shutdown_signal() {
    let interrupt = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = interrupt => {}
        () = terminate => {}
    }
    tracing::info!("shutting down");
}

//! `impostor-server`: the HTTP service (see the library docs and README).

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use server::{AppState, Config, auth, run};

/// HTTP service for impostor placement jobs.
///
/// Serving needs either `--tokens FILE` (every request then needs a token
/// of that file, made with `impostor-server token add`) or `--no-auth`
/// with a loopback `--listen`.
#[derive(Parser)]
#[command(
    name = "impostor-server",
    version,
    about,
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    serve: Serve,
}

#[derive(Subcommand)]
enum Command {
    /// Manage the API tokens of a tokens file.
    #[command(subcommand)]
    Token(TokenCommand),
    /// Run jobs without serving HTTP: claim them from a shared PostgreSQL
    /// database (`FOR UPDATE SKIP LOCKED`), under leases renewed while they
    /// run, until SIGTERM or SIGINT (then running jobs stop and their
    /// leases are given back, queued again for another worker).
    Worker(WorkerArgs),
}

#[derive(Args)]
struct WorkerArgs {
    /// The job database, shared with the API processes: postgres://…
    #[arg(long, value_name = "URL")]
    database: String,
    /// The local folder of this process's files (the artifact store's
    /// default, `<data-dir>/jobs`, must then be the API processes' too).
    #[arg(long, default_value = "impostor-data")]
    data_dir: PathBuf,
    /// The artifact store shared with the API processes (see the server's
    /// --artifacts).
    #[arg(long, value_name = "URL")]
    artifacts: Option<String>,
    /// Jobs this process runs at once.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=256))]
    workers: u64,
    /// Threads its jobs use (default: one per core).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    threads: Option<u64>,
    #[command(flatten)]
    limits: JobLimits,
}

/// What every process that runs jobs takes.
#[derive(Args)]
struct JobLimits {
    /// How long a claim on a job lasts without renewal, seconds (renewed
    /// every third of it); a job whose worker died runs again after it.
    #[arg(long, value_name = "SECONDS", default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..=86_400))]
    lease_seconds: u64,
    /// The longest a job may run, seconds: it is stopped and ends `failed`
    /// (default: no limit).
    #[arg(long, value_name = "SECONDS", value_parser = clap::value_parser!(u64).range(1..))]
    job_max_seconds: Option<u64>,
    /// The most memory a job's placement may be predicted to need, GB: a
    /// job predicted to need more is placed in tiles that fit, and one no
    /// tiling fits ends `failed` before allocating it (default: the memory
    /// available: what the machine has free, plus what the process holds).
    #[arg(long, value_name = "GB", value_parser = parse_gb)]
    job_max_memory: Option<u64>,
}

/// What a server process does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Role {
    /// Serve HTTP and run jobs (the single-process default).
    All,
    /// Serve HTTP only; `impostor-server worker` processes run the jobs.
    Api,
}

#[derive(Subcommand)]
enum TokenCommand {
    /// Create a token for a tenant and print it (and nothing else) on
    /// stdout: the only time it is shown. The file keeps its SHA-256.
    Add {
        /// The tokens file (created, readable by its owner only, when missing).
        #[arg(long, value_name = "FILE")]
        tokens: PathBuf,
        /// The tenant the token acts for (letters, digits, '.', '_', '-').
        #[arg(long)]
        tenant: String,
    },
    /// List the tokens: id, tenant, creation time (never a token).
    List {
        /// The tokens file.
        #[arg(long, value_name = "FILE")]
        tokens: PathBuf,
    },
    /// Revoke a token by its id (as `token list` shows it); a running
    /// server refuses it within a second.
    Revoke {
        /// The tokens file.
        #[arg(long, value_name = "FILE")]
        tokens: PathBuf,
        /// The token's id.
        id: String,
    },
}

#[derive(Args)]
struct Serve {
    /// The tokens file: every /v1 request needs `Authorization: Bearer
    /// <token>` with a token of it, and sees its tenant's jobs only.
    #[arg(long, value_name = "FILE")]
    tokens: Option<PathBuf>,
    /// No authentication: anyone who reaches the port sees, submits and
    /// deletes every job. Only with a loopback --listen.
    #[arg(long, conflicts_with = "tokens")]
    no_auth: bool,
    /// The most jobs one tenant may have queued or running (default: no
    /// limit but --max-queue); more are answered 429 before the upload.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    tenant_max_jobs: Option<u64>,
    /// The most /v1 requests per second one tenant may make, in bursts of
    /// as many; more are answered 429 with Retry-After (default: no limit).
    #[arg(long, value_name = "PER_SECOND", value_parser = clap::value_parser!(u32).range(1..))]
    rate_limit: Option<u32>,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    listen: String,
    /// Directory of the SQLite database, of uploads being received and,
    /// by default, of the job files (`<data-dir>/jobs`).
    #[arg(long, default_value = "impostor-data")]
    data_dir: PathBuf,
    /// Where the job files (inputs and results) are kept: a folder or
    /// `file:///path` (shared by every process, e.g. on a network file
    /// system), or an S3-compatible bucket `s3://bucket/prefix` configured
    /// by the AWS_* variables (AWS_ENDPOINT, AWS_REGION, AWS_ACCESS_KEY_ID,
    /// AWS_SECRET_ACCESS_KEY, AWS_ALLOW_HTTP for a plain-HTTP endpoint).
    /// Default: `<data-dir>/jobs`.
    #[arg(long, value_name = "URL")]
    artifacts: Option<String>,
    /// The job database: `sqlite:PATH` (default `<data-dir>/jobs.sqlite`)
    /// or `postgres://user@host:port/db`, shared by every API and worker
    /// process (with the same --artifacts).
    #[arg(long, value_name = "URL")]
    database: Option<String>,
    /// `all`: serve and run jobs; `api`: serve only (workers elsewhere).
    #[arg(long, value_enum, default_value_t = Role::All)]
    role: Role,
    /// Worker threads (jobs running at once) with --role all.
    #[arg(long, default_value_t = 1)]
    workers: usize,
    /// Largest upload, MiB.
    #[arg(long, default_value_t = 256)]
    max_upload_mb: usize,
    /// Most jobs waiting in the queue.
    #[arg(long, default_value_t = 64)]
    max_queue: usize,
    #[command(flatten)]
    limits: JobLimits,
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Token(cmd)) => token(cmd),
        Some(Command::Worker(args)) => worker(args),
        None => serve(cli.serve),
    }
}

/// `impostor-server token …`: exit 0, or 2 with the error on stderr.
fn token(cmd: TokenCommand) -> ExitCode {
    let result = match cmd {
        TokenCommand::Add { tokens, tenant } => {
            auth::add(&tokens, &tenant).map(|token| println!("{token}"))
        }
        TokenCommand::List { tokens } => auth::list(&tokens).map(|entries| {
            println!("{:<10} {:<24} created (UTC, ms since 1970)", "id", "tenant");
            for t in entries {
                println!("{:<10} {:<24} {}", t.id, t.tenant, t.created_ms);
            }
        }),
        TokenCommand::Revoke { tokens, id } => auth::revoke(&tokens, &id)
            .map(|t| eprintln!("revoked token {} of tenant {}", t.id, t.tenant)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

/// Serves until SIGINT or SIGTERM: exit 0; 2 for a bad configuration, 1
/// when the server cannot start or fails.
fn serve(cli: Serve) -> ExitCode {
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: cannot start the runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    runtime.block_on(serve_async(cli))
}

async fn serve_async(cli: Serve) -> ExitCode {
    init_tracing();
    if cli.tokens.is_none() && !cli.no_auth {
        eprintln!(
            "error: give --tokens FILE (create one with `impostor-server token add --tokens \
             FILE --tenant NAME`), or --no-auth with a loopback --listen for local use"
        );
        return ExitCode::from(2);
    }
    let mut cfg = Config::new(cli.data_dir);
    cfg.workers = match cli.role {
        Role::All => cli.workers.max(1),
        Role::Api => 0,
    };
    cfg.database = cli.database;
    cfg.artifacts = cli.artifacts;
    cli.limits.apply(&mut cfg);
    cfg.max_upload_mb = cli.max_upload_mb.max(1);
    cfg.max_queue = cli.max_queue.max(1);
    cfg.retain_days = cli.retain_days;
    cfg.tokens = cli.tokens;
    cfg.tenant_max_jobs = cli.tenant_max_jobs.map(|n| n as usize);
    cfg.rate_limit = cli.rate_limit;
    let listener = match tokio::net::TcpListener::bind(&cli.listen).await {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: cannot listen on {}: {e}", cli.listen);
            return ExitCode::FAILURE;
        }
    };
    let addr = match listener.local_addr() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    if cli.no_auth {
        if !addr.ip().is_loopback() {
            eprintln!(
                "error: --no-auth serves every job to anyone who reaches the port: it needs a \
                 loopback --listen (127.0.0.1 or [::1]), not {addr}; use --tokens FILE"
            );
            return ExitCode::from(2);
        }
        tracing::warn!(
            "NO AUTHENTICATION (--no-auth): every process on this machine can see, submit and \
             delete every job on {addr}"
        );
    }
    // The database client blocks: off the runtime's scheduling.
    let state = match tokio::task::block_in_place(|| AppState::open(cfg)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    tracing::info!("listening on {addr}");
    let served = run(listener, state.clone(), shutdown_signal()).await;
    // Running jobs stop and give their leases back.
    tokio::task::block_in_place(|| state.shutdown());
    match served {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

impl JobLimits {
    fn apply(&self, cfg: &mut Config) {
        cfg.lease = std::time::Duration::from_secs(self.lease_seconds);
        cfg.job_max_seconds = self.job_max_seconds;
        cfg.job_max_memory_bytes = self.job_max_memory;
    }
}

/// `impostor-server worker`: runs jobs until SIGTERM or SIGINT: exit 0; 2
/// when the database cannot be opened.
fn worker(args: WorkerArgs) -> ExitCode {
    init_tracing();
    if !(args.database.starts_with("postgres://") || args.database.starts_with("postgresql://")) {
        eprintln!(
            "error: a worker process needs a database shared with the API processes: \
             --database postgres://…, not {:?} (with SQLite, one `impostor-server` process \
             serves and runs jobs)",
            args.database
        );
        return ExitCode::from(2);
    }
    if let Some(n) = args.threads
        && let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n as usize)
            .build_global()
    {
        eprintln!("error: cannot start {n} threads: {e}");
        return ExitCode::FAILURE;
    }
    let mut cfg = Config::new(args.data_dir);
    cfg.workers = args.workers as usize;
    cfg.database = Some(args.database);
    cfg.artifacts = args.artifacts;
    args.limits.apply(&mut cfg);
    let state = match AppState::open(cfg) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    tracing::info!(workers = args.workers, "worker started");
    match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt.block_on(shutdown_signal()),
        Err(e) => {
            eprintln!("error: cannot start the runtime: {e}");
            return ExitCode::FAILURE;
        }
    }
    state.shutdown();
    tracing::info!("worker stopped");
    ExitCode::SUCCESS
}

fn init_tracing() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
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

//! The job database behind one small interface, on two engines: SQLite (a
//! file in the data folder; the single-process default) and PostgreSQL
//! (shared by any number of API and worker processes). The store writes
//! each statement once, with `?N` placeholders (SQLite's syntax, turned
//! into PostgreSQL's `$N`), in the SQL both engines accept; the few
//! statements that differ (claiming a job: `FOR UPDATE SKIP LOCKED`) ask
//! [`Db::backend`].
//!
//! Schemas come from the migrations in `server/migrations/<engine>/`,
//! applied in order on open and recorded in `schema_migrations`; on
//! PostgreSQL under an advisory lock, so processes starting together apply
//! each once.

use std::io;
use std::path::Path;
use std::sync::{Mutex, MutexGuard};

/// The engine behind a [`Db`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Backend {
    Sqlite,
    Postgres,
}

/// A statement's parameter or a column's value. Nulls keep their type
/// (PostgreSQL checks a parameter's type even when it is null).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Value {
    Int(Option<i64>),
    Real(Option<f64>),
    Text(Option<String>),
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Value::Int(Some(v))
    }
}
impl From<Option<i64>> for Value {
    fn from(v: Option<i64>) -> Self {
        Value::Int(v)
    }
}
impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Real(Some(v))
    }
}
impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::Text(Some(v.to_string()))
    }
}
impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::Text(Some(v))
    }
}
impl From<Option<&str>> for Value {
    fn from(v: Option<&str>) -> Self {
        Value::Text(v.map(str::to_string))
    }
}

/// One row of a query's answer, its columns in the order selected.
#[derive(Clone, Debug, Default)]
pub(crate) struct Row(Vec<Value>);

impl Row {
    /// Column `i` as an integer (`None`: null, absent or not an integer).
    pub fn int(&self, i: usize) -> Option<i64> {
        match self.0.get(i)? {
            Value::Int(v) => *v,
            _ => None,
        }
    }

    /// Column `i` as a number.
    pub fn real(&self, i: usize) -> Option<f64> {
        match self.0.get(i)? {
            Value::Real(v) => *v,
            Value::Int(v) => v.map(|v| v as f64),
            Value::Text(_) => None,
        }
    }

    /// Column `i` as text.
    pub fn text(&self, i: usize) -> Option<String> {
        match self.0.get(i)? {
            Value::Text(v) => v.clone(),
            _ => None,
        }
    }
}

/// A connection to the job database. A PostgreSQL connection that broke
/// (the server restarted, the network failed) is opened again by the next
/// statement.
pub(crate) enum Db {
    Sqlite(Mutex<rusqlite::Connection>),
    Postgres {
        url: String,
        client: Box<Mutex<Option<postgres::Client>>>,
    },
}

impl Drop for Db {
    /// The PostgreSQL client closes its connection by blocking on a runtime
    /// of its own, which must not happen on an async runtime's thread: it
    /// is dropped on a thread of its own there.
    fn drop(&mut self) {
        if let Db::Postgres { client, .. } = self
            && let Ok(c) = client.get_mut()
            && let Some(c) = c.take()
            && tokio::runtime::Handle::try_current().is_ok()
        {
            let _ = std::thread::Builder::new()
                .name("db-close".into())
                .spawn(move || drop(c));
        }
    }
}

/// The PostgreSQL client of `slot`, connected to `url` anew when it has
/// none or its connection is closed.
fn pg_client<'a>(
    slot: &'a mut Option<postgres::Client>,
    url: &str,
) -> io::Result<&'a mut postgres::Client> {
    if slot.as_ref().is_none_or(postgres::Client::is_closed) {
        *slot = Some(
            postgres::Client::connect(url, postgres::NoTls)
                .map_err(|e| io::Error::other(format!("cannot connect to the database: {e}")))?,
        );
    }
    slot.as_mut()
        .ok_or_else(|| io::Error::other("no database connection"))
}

/// The migrations of each engine, in order: (version, SQL).
const SQLITE_MIGRATIONS: &[(i64, &str)] = &[
    (1, include_str!("../migrations/sqlite/0001_leases.sql")),
    (2, include_str!("../migrations/sqlite/0002_tiles.sql")),
];
const POSTGRES_MIGRATIONS: &[(i64, &str)] = &[
    (1, include_str!("../migrations/postgres/0001_jobs.sql")),
    (2, include_str!("../migrations/postgres/0002_tiles.sql")),
];

fn sqlite_err(e: rusqlite::Error) -> io::Error {
    io::Error::other(e)
}

fn pg_err(e: postgres::Error) -> io::Error {
    io::Error::other(e)
}

/// `?N` placeholders as PostgreSQL's `$N` (no statement of the store has a
/// `?` anywhere else).
fn to_postgres(sql: &str) -> String {
    sql.replace('?', "$")
}

/// A parameter as PostgreSQL takes it.
fn pg_param(v: &Value) -> Box<dyn postgres::types::ToSql + Sync + '_> {
    match v {
        Value::Int(x) => Box::new(*x),
        Value::Real(x) => Box::new(*x),
        Value::Text(x) => Box::new(x.as_deref()),
    }
}

impl rusqlite::ToSql for Value {
    fn to_sql(&self) -> rusqlite::Result<rusqlite::types::ToSqlOutput<'_>> {
        use rusqlite::types::{ToSqlOutput, Value as V};
        Ok(match self {
            Value::Int(x) => ToSqlOutput::Owned(x.map_or(V::Null, V::Integer)),
            Value::Real(x) => ToSqlOutput::Owned(x.map_or(V::Null, V::Real)),
            Value::Text(x) => match x {
                Some(s) => ToSqlOutput::from(s.as_str()),
                None => ToSqlOutput::Owned(V::Null),
            },
        })
    }
}

impl Db {
    /// Opens the database `url`: `postgres://…` (or `postgresql://…`), or
    /// `sqlite:PATH`; `None` is `<data_dir>/jobs.sqlite`. `sqlite_setup`
    /// runs on a SQLite database before its migrations (the tables of
    /// versions from before migrations existed).
    pub fn open(
        url: Option<&str>,
        data_dir: &Path,
        sqlite_setup: impl FnOnce(&rusqlite::Connection) -> io::Result<()>,
    ) -> io::Result<Db> {
        match url {
            Some(u) if u.starts_with("postgres://") || u.starts_with("postgresql://") => {
                let mut slot = None;
                pg_client(&mut slot, u)?;
                let db = Db::Postgres {
                    url: u.to_string(),
                    client: Box::new(Mutex::new(slot)),
                };
                db.migrate()?;
                Ok(db)
            }
            Some(u) if u.starts_with("sqlite:") => {
                Self::open_sqlite(Path::new(&u["sqlite:".len()..]), sqlite_setup)
            }
            Some(u) => Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("--database must be sqlite:PATH or postgres://…, not {u:?}"),
            )),
            None => Self::open_sqlite(&data_dir.join("jobs.sqlite"), sqlite_setup),
        }
    }

    fn open_sqlite(
        path: &Path,
        setup: impl FnOnce(&rusqlite::Connection) -> io::Result<()>,
    ) -> io::Result<Db> {
        let conn = rusqlite::Connection::open(path).map_err(sqlite_err)?;
        conn.execute_batch("PRAGMA journal_mode = WAL; PRAGMA synchronous = FULL;")
            .map_err(sqlite_err)?;
        setup(&conn)?;
        let db = Db::Sqlite(Mutex::new(conn));
        db.migrate()?;
        Ok(db)
    }

    /// The engine.
    pub fn backend(&self) -> Backend {
        match self {
            Db::Sqlite(_) => Backend::Sqlite,
            Db::Postgres { .. } => Backend::Postgres,
        }
    }

    fn lock<T>(m: &Mutex<T>) -> io::Result<MutexGuard<'_, T>> {
        m.lock().map_err(|e| io::Error::other(e.to_string()))
    }

    /// Applies the migrations not yet recorded, each in a transaction of
    /// its own.
    fn migrate(&self) -> io::Result<()> {
        const TABLE: &str =
            "CREATE TABLE IF NOT EXISTS schema_migrations (version BIGINT PRIMARY KEY)";
        match self {
            Db::Sqlite(c) => {
                let mut c = Self::lock(c)?;
                c.execute_batch(TABLE).map_err(sqlite_err)?;
                for &(version, sql) in SQLITE_MIGRATIONS {
                    let tx = c.transaction().map_err(sqlite_err)?;
                    let done: bool = tx
                        .query_row(
                            "SELECT EXISTS (SELECT 1 FROM schema_migrations WHERE version = ?1)",
                            [version],
                            |r| r.get(0),
                        )
                        .map_err(sqlite_err)?;
                    if !done {
                        tx.execute_batch(sql).map_err(sqlite_err)?;
                        tx.execute("INSERT INTO schema_migrations VALUES (?1)", [version])
                            .map_err(sqlite_err)?;
                    }
                    tx.commit().map_err(sqlite_err)?;
                }
            }
            Db::Postgres { url, client } => {
                let mut slot = Self::lock(client)?;
                let c = pg_client(&mut slot, url)?;
                for &(version, sql) in POSTGRES_MIGRATIONS {
                    let mut tx = c.transaction().map_err(pg_err)?;
                    // One process at a time (held to the end of the transaction).
                    tx.execute("SELECT pg_advisory_xact_lock(7305412)", &[])
                        .map_err(pg_err)?;
                    tx.batch_execute(TABLE).map_err(pg_err)?;
                    let done = tx
                        .query_opt(
                            "SELECT 1 FROM schema_migrations WHERE version = $1",
                            &[&version],
                        )
                        .map_err(pg_err)?
                        .is_some();
                    if !done {
                        tx.batch_execute(sql).map_err(pg_err)?;
                        tx.execute("INSERT INTO schema_migrations VALUES ($1)", &[&version])
                            .map_err(pg_err)?;
                    }
                    tx.commit().map_err(pg_err)?;
                }
            }
        }
        Ok(())
    }

    /// Runs a statement; returns the rows it changed.
    pub fn execute(&self, sql: &str, params: &[Value]) -> io::Result<u64> {
        match self {
            Db::Sqlite(c) => Self::lock(c)?
                .execute(sql, rusqlite::params_from_iter(params))
                .map(|n| n as u64)
                .map_err(sqlite_err),
            Db::Postgres { url, client } => {
                let boxed: Vec<_> = params.iter().map(pg_param).collect();
                let refs: Vec<&(dyn postgres::types::ToSql + Sync)> =
                    boxed.iter().map(|b| b.as_ref()).collect();
                let mut slot = Self::lock(client)?;
                pg_client(&mut slot, url)?
                    .execute(&to_postgres(sql), &refs)
                    .map_err(pg_err)
            }
        }
    }

    /// Runs a query (or a statement with `RETURNING`); returns its rows.
    pub fn query(&self, sql: &str, params: &[Value]) -> io::Result<Vec<Row>> {
        match self {
            Db::Sqlite(c) => {
                let c = Self::lock(c)?;
                let mut stmt = c.prepare(sql).map_err(sqlite_err)?;
                let n = stmt.column_count();
                let rows = stmt
                    .query_map(rusqlite::params_from_iter(params), |r| {
                        use rusqlite::types::ValueRef;
                        (0..n)
                            .map(|i| {
                                Ok(match r.get_ref(i)? {
                                    ValueRef::Integer(v) => Value::Int(Some(v)),
                                    ValueRef::Real(v) => Value::Real(Some(v)),
                                    ValueRef::Text(t) => {
                                        Value::Text(Some(String::from_utf8_lossy(t).into_owned()))
                                    }
                                    ValueRef::Null | ValueRef::Blob(_) => Value::Int(None),
                                })
                            })
                            .collect::<rusqlite::Result<Vec<Value>>>()
                            .map(Row)
                    })
                    .map_err(sqlite_err)?
                    .collect::<rusqlite::Result<Vec<Row>>>()
                    .map_err(sqlite_err)?;
                Ok(rows)
            }
            Db::Postgres { url, client } => {
                use postgres::types::Type;
                let boxed: Vec<_> = params.iter().map(pg_param).collect();
                let refs: Vec<&(dyn postgres::types::ToSql + Sync)> =
                    boxed.iter().map(|b| b.as_ref()).collect();
                let mut slot = Self::lock(client)?;
                let rows = pg_client(&mut slot, url)?
                    .query(&to_postgres(sql), &refs)
                    .map_err(pg_err)?;
                rows.iter()
                    .map(|r| {
                        (0..r.len())
                            .map(|i| {
                                let ty = r.columns()[i].type_();
                                Ok(if *ty == Type::INT8 {
                                    Value::Int(r.try_get(i)?)
                                } else if *ty == Type::INT4 {
                                    Value::Int(r.try_get::<_, Option<i32>>(i)?.map(i64::from))
                                } else if *ty == Type::BOOL {
                                    Value::Int(r.try_get::<_, Option<bool>>(i)?.map(i64::from))
                                } else if *ty == Type::FLOAT8 {
                                    Value::Real(r.try_get(i)?)
                                } else {
                                    Value::Text(r.try_get(i)?)
                                })
                            })
                            .collect::<Result<Vec<Value>, postgres::Error>>()
                            .map(Row)
                            .map_err(pg_err)
                    })
                    .collect()
            }
        }
    }

    /// The first row of a query, if any.
    pub fn query_one(&self, sql: &str, params: &[Value]) -> io::Result<Option<Row>> {
        Ok(self.query(sql, params)?.into_iter().next())
    }

    /// Whether the database answers (`/healthz`).
    pub fn ping(&self) -> io::Result<()> {
        self.query("SELECT 1", &[]).map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_become_postgres_ones() {
        assert_eq!(
            to_postgres("UPDATE jobs SET a = ?2 WHERE id = ?1 AND (?3 IS NULL OR t = ?3)"),
            "UPDATE jobs SET a = $2 WHERE id = $1 AND ($3 IS NULL OR t = $3)"
        );
    }
}

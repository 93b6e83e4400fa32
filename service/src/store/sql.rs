//! One statement, run on either database: the store's SQL is written once, with `$N` placeholders
//! (which SQLite reads as PostgreSQL does), its arguments collected as plain values ([`Sql`]) and
//! bound on whichever connection runs it ([`Conn`]). Rows come back as [`AnyRow`], read through
//! by column name. This is the only place that names both databases' sqlx types.

use super::StoreResult;
use futures_util::stream::{BoxStream, StreamExt, TryStreamExt};
use sqlx::pool::PoolConnection;
use sqlx::postgres::PgRow;
use sqlx::sqlite::SqliteRow;
use sqlx::{
    AssertSqlSafe, Database, Encode, PgConnection, PgPool, Postgres, Sqlite, SqliteConnection,
    SqlitePool, Transaction, Type,
};
use std::borrow::Cow;

/// Runs `$body` with the query of `$sql` bound for the connection's database (`$query`), the
/// executor (`$executor`) and the wrapping of its rows into [`AnyRow`] (`$row`).
macro_rules! on_either {
    ($conn:expr, $sql:expr, |$query:ident, $executor:ident, $row:ident| $body:expr) => {
        match $conn {
            Conn::Sqlite($executor) => {
                let ($query, $row) = ($sql.for_sqlite().on::<Sqlite>(), AnyRow::Sqlite);
                $body
            }
            Conn::SqlitePool($executor) => {
                let ($query, $row) = ($sql.for_sqlite().on::<Sqlite>(), AnyRow::Sqlite);
                $body
            }
            Conn::Postgres($executor) => {
                let ($query, $row) = ($sql.on::<Postgres>(), AnyRow::Postgres);
                $body
            }
            Conn::PostgresPool($executor) => {
                let ($query, $row) = ($sql.on::<Postgres>(), AnyRow::Postgres);
                $body
            }
        }
    };
}

/// One value bound to a statement.
#[derive(Debug, Clone)]
pub(crate) enum Arg {
    Int(Option<i64>),
    Real(Option<f64>),
    Text(Option<String>),
    Bytes(Option<Vec<u8>>),
    Flag(bool),
}

macro_rules! arg_from {
    ($($t:ty => $variant:ident($convert:expr)),* $(,)?) => {
        $(impl From<$t> for Arg {
            fn from(value: $t) -> Self {
                Arg::$variant($convert(value))
            }
        })*
    };
}

arg_from! {
    i64 => Int(Some),
    Option<i64> => Int(std::convert::identity),
    f64 => Real(Some),
    Option<f64> => Real(std::convert::identity),
    String => Text(Some),
    &str => Text(|s: &str| Some(s.to_owned())),
    Option<String> => Text(std::convert::identity),
    Vec<u8> => Bytes(Some),
    Option<Vec<u8>> => Bytes(std::convert::identity),
    bool => Flag(std::convert::identity),
}

impl Arg {
    /// The bytes it takes in a statement's arguments, as PostgreSQL sends it: a length, then the
    /// value.
    fn size(&self) -> usize {
        let value = match self {
            Arg::Int(_) | Arg::Real(_) => 8,
            Arg::Text(text) => text.as_ref().map_or(0, String::len),
            Arg::Bytes(bytes) => bytes.as_ref().map_or(0, Vec::len),
            Arg::Flag(_) => 1,
        };
        4 + value
    }
}

/// A statement of the shared SQL and its arguments, `$1` first.
#[derive(Debug)]
pub(crate) struct Sql {
    text: Cow<'static, str>,
    args: Vec<Arg>,
    /// Whether its placeholders are `$1, $2, ..` in order, each once ([`Sql::in_order`]).
    in_order: bool,
}

impl Sql {
    pub(crate) fn new(text: &'static str) -> Self {
        Self {
            text: Cow::Borrowed(text),
            args: Vec::new(),
            in_order: false,
        }
    }

    /// A statement made at run time whose placeholders are `$1, $2, ..` in order, each once (rows
    /// of values): SQLite runs it with anonymous `?`, which sqlx binds by position. A `$N` it finds
    /// by a scan of the statement's parameter names at every bind, quadratic in the parameters:
    /// the 115 rows of a small job's distributions spent 0.75 ms of SQLite's thread there, ten
    /// times the statements' own execution.
    pub(crate) fn in_order(text: String) -> Self {
        debug_assert!(
            placeholders(&text).eq(1..=placeholders(&text).count()),
            "placeholders in order, each once: {text}"
        );
        Self {
            text: Cow::Owned(text),
            args: Vec::new(),
            in_order: true,
        }
    }

    /// The statement as SQLite runs it: [`Sql::in_order`]'s placeholders anonymous.
    fn for_sqlite(mut self) -> Self {
        if self.in_order {
            let mut text = String::with_capacity(self.text.len());
            let mut chars = self.text.chars().peekable();
            while let Some(c) = chars.next() {
                if c == '$' && chars.peek().is_some_and(char::is_ascii_digit) {
                    text.push('?');
                    while chars.next_if(char::is_ascii_digit).is_some() {}
                } else {
                    text.push(c);
                }
            }
            self.text = Cow::Owned(text);
        }
        self
    }

    /// Binds the next parameter.
    pub(crate) fn bind(mut self, value: impl Into<Arg>) -> Self {
        self.args.push(value.into());
        self
    }

    /// Runs it; the rows it changed.
    pub(crate) async fn execute(self, on: impl Into<Conn<'_>>) -> StoreResult<u64> {
        Ok(on_either!(on.into(), self, |query, executor, _row| query?
            .execute(executor)
            .await?
            .rows_affected()))
    }

    pub(crate) async fn fetch_optional(
        self,
        on: impl Into<Conn<'_>>,
    ) -> StoreResult<Option<AnyRow>> {
        Ok(on_either!(on.into(), self, |query, executor, row| query?
            .fetch_optional(executor)
            .await?
            .map(row)))
    }

    pub(crate) async fn fetch_one(self, on: impl Into<Conn<'_>>) -> StoreResult<AnyRow> {
        Ok(on_either!(on.into(), self, |query, executor, row| row(
            query?.fetch_one(executor).await?
        )))
    }

    pub(crate) async fn fetch_all(self, on: impl Into<Conn<'_>>) -> StoreResult<Vec<AnyRow>> {
        Ok(on_either!(on.into(), self, |query, executor, row| query?
            .fetch_all(executor)
            .await?
            .into_iter()
            .map(row)
            .collect()))
    }

    /// The rows as they arrive, for results too large to hold at once.
    pub(crate) fn fetch<'c>(
        self,
        on: impl Into<Conn<'c>>,
    ) -> BoxStream<'c, Result<AnyRow, sqlx::Error>> {
        on_either!(on.into(), self, |query, executor, row| match query {
            Ok(query) => query.fetch(executor).map_ok(row).boxed(),
            Err(error) => futures_util::stream::once(std::future::ready(Err(error))).boxed(),
        })
    }

    /// The sqlx query of database `DB`, its arguments bound into a buffer sized for them all at
    /// once: binding one by one, PostgreSQL's buffer grew by doubling, and a Result's rows (2.7 MB
    /// for a 1000-device job) were copied through ever larger fresh allocations, each faulted in
    /// page by page, 10-30 ms of a merge step's write.
    /// A value that cannot be encoded (bytes beyond PostgreSQL's 1 GB) is an error of the
    /// statement, as sqlx gives it for a bound value.
    fn on<DB: Database>(self) -> Result<sqlx::query::Query<'static, DB, DB::Arguments>, sqlx::Error>
    where
        DB::Arguments: sqlx::IntoArguments<DB>,
        for<'t> Option<i64>: Encode<'t, DB> + Type<DB>,
        for<'t> Option<f64>: Encode<'t, DB> + Type<DB>,
        for<'t> Option<String>: Encode<'t, DB> + Type<DB>,
        for<'t> Option<Vec<u8>>: Encode<'t, DB> + Type<DB>,
        for<'t> bool: Encode<'t, DB> + Type<DB>,
    {
        use sqlx::Arguments;
        let mut arguments = DB::Arguments::default();
        arguments.reserve(self.args.len(), self.args.iter().map(Arg::size).sum());
        let bound = self.args.into_iter().try_for_each(|arg| match arg {
            Arg::Int(value) => arguments.add(value),
            Arg::Real(value) => arguments.add(value),
            Arg::Text(value) => arguments.add(value),
            Arg::Bytes(value) => arguments.add(value),
            Arg::Flag(value) => arguments.add(value),
        });
        bound.map_err(sqlx::Error::Encode)?;
        Ok(match self.text {
            Cow::Borrowed(text) => sqlx::query_with(text, arguments),
            Cow::Owned(text) => sqlx::query_with(AssertSqlSafe(text), arguments),
        })
    }
}

/// The numbers of the `$N` placeholders of `text`, in order.
fn placeholders(text: &str) -> impl Iterator<Item = usize> + '_ {
    text.split('$').skip(1).map(|after| {
        let digits = after.bytes().take_while(u8::is_ascii_digit).count();
        after[..digits].parse().unwrap_or(0)
    })
}

/// Where a statement runs: a connection (in a transaction or not) or a pool of either database.
pub(crate) enum Conn<'c> {
    Sqlite(&'c mut SqliteConnection),
    SqlitePool(&'c SqlitePool),
    Postgres(&'c mut PgConnection),
    PostgresPool(&'c PgPool),
}

/// A transaction on either database.
pub(crate) enum Tx {
    Sqlite(Transaction<'static, Sqlite>),
    Postgres(Transaction<'static, Postgres>),
}

impl Tx {
    pub(crate) async fn commit(self) -> StoreResult<()> {
        match self {
            Tx::Sqlite(tx) => tx.commit().await?,
            Tx::Postgres(tx) => tx.commit().await?,
        }
        Ok(())
    }

    pub(crate) async fn rollback(self) -> StoreResult<()> {
        match self {
            Tx::Sqlite(tx) => tx.rollback().await?,
            Tx::Postgres(tx) => tx.rollback().await?,
        }
        Ok(())
    }
}

impl<'c> From<&'c mut Tx> for Conn<'c> {
    fn from(tx: &'c mut Tx) -> Self {
        match tx {
            Tx::Sqlite(tx) => Conn::Sqlite(tx),
            Tx::Postgres(tx) => Conn::Postgres(tx),
        }
    }
}

/// One connection of either pool, held for several statements.
pub(crate) enum Pooled {
    Sqlite(PoolConnection<Sqlite>),
    Postgres(PoolConnection<Postgres>),
}

impl<'c> From<&'c mut Pooled> for Conn<'c> {
    fn from(connection: &'c mut Pooled) -> Self {
        match connection {
            Pooled::Sqlite(connection) => Conn::Sqlite(connection),
            Pooled::Postgres(connection) => Conn::Postgres(connection),
        }
    }
}

/// A row of either database.
pub(crate) enum AnyRow {
    Sqlite(SqliteRow),
    Postgres(PgRow),
}

macro_rules! delegate {
    ($($method:ident -> $t:ty),* $(,)?) => {
        $(pub(crate) fn $method(&self, column: &str) -> Result<$t, sqlx::Error> {
            match self {
                AnyRow::Sqlite(row) => sqlx::Row::try_get(row, column),
                AnyRow::Postgres(row) => sqlx::Row::try_get(row, column),
            }
        })*
    };
}

/// Read by column name into the few types the schema uses.
impl AnyRow {
    delegate! {
        int -> i64,
        maybe_int -> Option<i64>,
        text -> String,
        maybe_text -> Option<String>,
        flag -> bool,
        bytes -> Vec<u8>,
        maybe_bytes -> Option<Vec<u8>>,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_of_values_run_on_sqlite_with_anonymous_placeholders() {
        let sql = Sql::in_order("INSERT INTO t VALUES ($1, $2, 'queued'), ($3, $4)".to_owned())
            .for_sqlite();
        assert_eq!(sql.text, "INSERT INTO t VALUES (?, ?, 'queued'), (?, ?)");
        let shared = Sql::new("SELECT * FROM t WHERE a = $1 OR b = $1").for_sqlite();
        assert_eq!(shared.text, "SELECT * FROM t WHERE a = $1 OR b = $1");
        let many: Vec<String> = (1..=12).map(|n| format!("${n}")).collect();
        let text = format!("VALUES ({})", many.join(", "));
        assert_eq!(
            placeholders(&text).collect::<Vec<_>>(),
            (1..=12).collect::<Vec<_>>()
        );
        let anonymous = Sql::in_order(text).for_sqlite();
        assert_eq!(anonymous.text, format!("VALUES ({})", ["?"; 12].join(", ")));
    }
}

//! Command line: `bouncewear simulate | calibrate | run | serve | worker | health | bench`, and
//! for a running server `submit | status | wait | fetch | cancel`.
//!
//! Bad input exits with code 2 and one line on stderr naming the field (a JSON pointer) and the rule.

mod bench;
mod measurements;
mod remote;

use crate::app::StartupError;
use crate::compute::PoolError;
use crate::domain::draw_seed;
use crate::progress::Progress;
use crate::telemetry::{self, LogFormat};
use bench::BenchError;
use bouncewear_model::calibration::{CalibrationSpec, calibrate};
use bouncewear_model::montecarlo::rare::check_threshold;
use bouncewear_model::montecarlo::{Job, Kernel, run_job};
use bouncewear_model::{Fidelity, InvalidInput, Pointer, Scenario, simulate};
use clap::{Parser, Subcommand, ValueEnum};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "bouncewear",
    version,
    propagate_version = true,
    about = "Monte Carlo wear simulation of bouncing electrical contacts (McBride & Sharkh 1992)"
)]
pub struct Cli {
    /// Log lines as `text` (coloured only when stderr is a terminal and `NO_COLOR` is not set) or
    /// `json` (one object a line).
    #[arg(
        long,
        global = true,
        value_enum,
        env = "BOUNCEWEAR_LOG_FORMAT",
        default_value_t = LogFormat::Text
    )]
    log_format: LogFormat,
    /// The kernel every job of this process runs on: `scalar` (one device at a time) or an
    /// instruction set this CPU runs (`portable`, `avx2`, `avx512`); the fastest when not given.
    /// Every kernel gives the same bits: a switch for comparing them, not for speed.
    #[arg(long, global = true, env = "BOUNCEWEAR_KERNEL", value_name = "NAME")]
    kernel: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate one make operation of a scenario and print its bounces as JSON.
    Simulate {
        /// Model fidelity: eq. 7 and exact flight, or the paper's closed-form approximations.
        #[arg(long, value_enum, default_value_t = FidelityArg::Exact)]
        fidelity: FidelityArg,
        /// Scenario JSON file; `-` or nothing reads standard input.
        #[arg(default_value = "-")]
        file: PathBuf,
    },
    /// Fit scenario parameters to measured operations and print the estimates, the fitted
    /// scenario and the residuals as JSON (docs/model.md "Calibration").
    Calibrate {
        /// Calibration JSON file: `{"scenario", "fit": ["material.kappa", ...], "observations":
        /// [...]}`; `-` or nothing reads standard input.
        #[arg(default_value = "-")]
        file: PathBuf,
        /// Also write the fit as an SVG file: simulated against measured, a panel per quantity.
        #[arg(long, value_name = "FILE")]
        plot: Option<PathBuf>,
        /// The observations from a CSV file instead, one per row, the header naming each column
        /// after an observation's field (`operation`, `impact_velocity_m_s`, `first_bounce_s`,
        /// `total_bounce_s`, `e1`, ...); an empty cell is a quantity not measured in that row.
        #[arg(long, value_name = "FILE.csv")]
        observations: Option<PathBuf>,
    },
    /// Run a Monte Carlo endurance job and print its Result as JSON.
    Run {
        /// Job JSON file; `-` reads standard input.
        file: PathBuf,
        /// Worker threads (default: one per core). Results are identical for any count.
        #[arg(long)]
        threads: Option<usize>,
        /// Also write the plots as SVG files into this directory: for every operation metric its
        /// wear curve (`bands-METRIC.svg`) and histograms (`histograms-METRIC.svg`); with failure
        /// criteria `weibull.svg`, with a rare event `tail.svg`, and with a sensitivity analysis,
        /// for every metric of it, `sensitivity-METRIC.svg`.
        #[arg(long)]
        plots: Option<PathBuf>,
        /// No progress bar (it is drawn only when stderr is a terminal anyway).
        #[arg(long, short)]
        quiet: bool,
    },
    /// Serve the HTTP API, with the job queue in an embedded SQLite database (or PostgreSQL).
    Serve(crate::config::ServeConfig),
    /// Run jobs from the queue's database without serving HTTP: more machines for one queue.
    Worker(crate::config::WorkerProcess),
    /// Ask a running server whether it is healthy: exit 0 when its `/healthz` answers 200, 1 when
    /// not (the Docker image's health check).
    Health {
        /// The health endpoint; a URL whose path ends in neither `/healthz` nor `/readyz` is a
        /// server's address, and its `/healthz` is asked.
        #[arg(
            long,
            env = "BOUNCEWEAR_HEALTH_URL",
            default_value = "http://127.0.0.1:8080/healthz",
            hide_env_values = true
        )]
        url: String,
        /// Seconds to wait for the answer.
        #[arg(long, default_value_t = 2.0, value_parser = remote::seconds)]
        timeout_seconds: f64,
    },
    /// Queue a job on a server (`--url`, `--api-key`) and print the job resource, or with `--wait`
    /// its Result once it succeeded, as `run` prints it.
    Submit {
        /// Job JSON file; `-` or nothing reads standard input.
        #[arg(default_value = "-")]
        file: PathBuf,
        /// Wait for the job to end and print its Result (exit 1 if it failed or was cancelled).
        #[arg(long)]
        wait: bool,
        /// With `--wait`: give up (exit 1) this many seconds after the submission began, its
        /// retries and the Result's fetch included.
        #[arg(long, requires = "wait", value_parser = remote::seconds)]
        timeout_seconds: Option<f64>,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Print a job of a server: its status, progress and links.
    Status {
        /// The job's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Wait until a job of a server ends; print it (exit 0 if it succeeded, 1 otherwise).
    Wait {
        /// The job's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
        /// Give up (exit 1) after this many seconds.
        #[arg(long, value_parser = remote::seconds)]
        timeout_seconds: Option<f64>,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Print a part of a succeeded job of a server, as the API serves it.
    Fetch {
        /// The job's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
        /// Which part.
        #[arg(value_enum, default_value_t = remote::Part::Result)]
        part: remote::Part,
        /// CSV instead of JSON (`life`: each device; `rare-event`: the tail curve).
        #[arg(long)]
        csv: bool,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Compare two succeeded jobs of a server, design a against design b: print the comparison
    /// (statistics per shared bin, B-lives, who outlasts whom, with intervals) as the API serves it.
    Compare {
        /// The first job's id (design a).
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        a: String,
        /// The second job's id (design b).
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        b: String,
        /// The metric compared (default `total_bounce_s`).
        #[arg(long)]
        metric: Option<String>,
        /// Comma-separated statistics (default `mean,p50,p95`): `mean`, `p01` ... `p99`,
        /// `exceedance`.
        #[arg(long)]
        statistics: Option<String>,
        /// Comma-separated fractions of the B-lives compared (default `0.01,0.1`).
        #[arg(long)]
        b_lives: Option<String>,
        /// Also write the overlaid plots, `bands.svg` (the wear curves of an operation metric; a
        /// device metric has none) and (with failure criteria) `weibull.svg`, into this directory.
        #[arg(long)]
        plots: Option<PathBuf>,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Cancel a queued or running job of a server; print it (a job that had ended, as it is: never deleted).
    Cancel {
        /// The job's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Nightly runs on a server: create, list, show, replace or delete a schedule, run it now,
    /// and print its runs' trend.
    Schedule {
        #[command(subcommand)]
        command: remote::ScheduleCommand,
        #[command(flatten)]
        server: remote::Server,
    },
    /// Measure speed against error and write report.json, report.md and report.svg.
    Bench {
        /// A smaller run that finishes in well under two minutes.
        #[arg(long)]
        quick: bool,
        /// Where to write the report.
        #[arg(long, default_value = "bench-report")]
        out: PathBuf,
        /// Seeds (jobs) each coverage figure is over (default 400, or 20 with `--quick`): more
        /// seeds, a smaller standard error of the coverage (1.1 points at 400, 0.55 at 1600).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
        coverage_seeds: Option<u32>,
        /// Measure only this part again, over the report `--out` holds (from a run with the
        /// same `--quick`), and keep its other figures as they are: the interval tables change
        /// with the code of an interval, not with the machine, while the speed does.
        #[arg(long, value_enum)]
        only: Option<bench::Only>,
        /// Worker threads (default: one per core).
        #[arg(long)]
        threads: Option<usize>,
        /// No progress bar (it is drawn only when stderr is a terminal anyway), and no note of
        /// where the report went.
        #[arg(long, short)]
        quiet: bool,
    },
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum FidelityArg {
    Exact,
    #[value(name = "closed_form")]
    ClosedForm,
}

impl From<FidelityArg> for Fidelity {
    fn from(arg: FidelityArg) -> Self {
        match arg {
            FidelityArg::Exact => Fidelity::Exact,
            FidelityArg::ClosedForm => Fidelity::ClosedForm,
        }
    }
}

/// Runs every job of this process on the kernel `name` (`--kernel`, `BOUNCEWEAR_KERNEL`).
fn choose_kernel(name: &str) -> Result<(), CliError> {
    let kernel = Kernel::named(name).ok_or_else(|| {
        let names = Kernel::names().join(", ");
        CliError::Usage(format!(
            "--kernel (BOUNCEWEAR_KERNEL) `{name}` is not a kernel this build runs on this CPU: \
             one of {names}"
        ))
    })?;
    Kernel::choose(kernel)
        .map_err(|active| CliError::Failed(format!("the kernel is already {}", active.name())))
}

/// Why a command failed, and so which exit code it gets.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// The user's document breaks a rule: exit 2.
    #[error("invalid input: {0}")]
    Invalid(#[from] InvalidInput),
    /// A flag the command cannot take as given (`--kernel`, `--threads`, `--csv`): exit 2, a bad
    /// command line, said as it is rather than as a document's fault.
    #[error("{0}")]
    Usage(String),
    /// A file could not be read: exit 2 too, it is the user's path.
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    /// An output could not be written (a full disk, a closed file): exit 1, a failure of the
    /// machine rather than of the input.
    #[error("{path}: {source}")]
    Write {
        path: String,
        source: std::io::Error,
    },
    /// `serve` could not start: exit 2 when its configuration is at fault, 1 otherwise.
    #[error(transparent)]
    Startup(#[from] StartupError),
    /// A job waited for ended without succeeding, or had not ended at the timeout: the job
    /// resource is printed (a script learns the id of a job it submitted), then the reason, exit 1.
    #[error("{reason}")]
    Ended { job: String, reason: String },
    /// Anything else: exit 1.
    #[error("{0}")]
    Failed(String),
}

impl CliError {
    fn exit_code(&self) -> ExitCode {
        ExitCode::from(self.code())
    }

    /// The process's exit status: 2 for the user's input or command line, 1 otherwise.
    fn code(&self) -> u8 {
        match self {
            CliError::Invalid(_) | CliError::Usage(_) | CliError::Io { .. } => 2,
            CliError::Startup(error) if error.is_bad_command_line() => 2,
            CliError::Startup(_)
            | CliError::Ended { .. }
            | CliError::Write { .. }
            | CliError::Failed(_) => 1,
        }
    }
}

impl From<PoolError> for CliError {
    fn from(error: PoolError) -> Self {
        match error {
            PoolError::NoThreads | PoolError::TooMany(_) => {
                let given = match error {
                    PoolError::TooMany(threads) => threads,
                    _ => 0,
                };
                let most = crate::compute::MAX_THREADS;
                CliError::Usage(format!("--threads must be from 1 to {most}, got {given}"))
            }
            PoolError::Build(_) => CliError::Failed(error.to_string()),
        }
    }
}

/// The report's directory was made before the bench ran ([`output_directory`]): a file of it
/// that cannot be written then is a failure, exit 1. The report `--only` measures again is the
/// user's path: missing or not a report, exit 2.
impl From<BenchError> for CliError {
    fn from(error: BenchError) -> Self {
        match error {
            BenchError::Write { path, source } => CliError::Write { path, source },
            BenchError::Read { path, source } => CliError::Io { path, source },
            error @ BenchError::NotTheReport { .. } => CliError::Usage(error.to_string()),
        }
    }
}

/// Makes the directory a command writes its outputs into (`--plots`, `--out`) before any work:
/// a path that cannot be one is a bad command line (exit 2) at once, not after a run of hours
/// whose Result it would throw away (found from outside: `run --plots FILE` ran the job, then
/// exited with "File exists" and printed nothing).
/// A directory that exists but takes no file (`/proc/self`, one without write permission) is
/// found by writing a file there and removing it: it failed after the run before.
/// Whether it made the directory ([`unless_failed`] takes it away again).
fn output_directory(flag: &str, dir: &Path) -> Result<bool, CliError> {
    let usage = |source: std::io::Error| {
        CliError::Usage(format!(
            "{flag} {}: cannot be made a directory for the outputs ({source})",
            dir.display()
        ))
    };
    let made = !dir.exists();
    std::fs::create_dir_all(dir).map_err(usage)?;
    let probe = dir.join(format!(".bouncewear-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(usage)?;
    std::fs::remove_file(&probe).map_err(usage)?;
    Ok(made)
}

/// `outcome`, with the output directory the command made taken away again if it failed and
/// left it empty (a failed `compare --plots DIR` left `DIR`, empty, behind).
fn unless_failed<T>(
    outcome: Result<T, CliError>,
    made: Option<(&Path, bool)>,
) -> Result<T, CliError> {
    if outcome.is_err()
        && let Some((dir, true)) = made
    {
        // Only an empty directory goes.
        let _ = std::fs::remove_dir(dir);
    }
    outcome
}

/// `text` on one line and inert on a terminal: its control characters escaped (`\n`,
/// `\u{1b}`). An unknown member's name is quoted as the input spelled it: `{"a\nb": 1}` split the
/// one line stderr gets, and an escape sequence in a name reached the terminal (found from
/// outside).
fn one_line(text: &str) -> String {
    let mut line = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            line.extend(c.escape_default());
        } else {
            line.push(c);
        }
    }
    line
}

/// One line on stderr, `bouncewear: ` first. A stderr that cannot take it (a full disk, a closed
/// pipe) changes nothing of the exit status: `eprintln!` panicked there, and exit 2 or 1 became
/// 101 (found from outside).
fn stderr_line(line: std::fmt::Arguments) {
    let _ = writeln!(std::io::stderr().lock(), "bouncewear: {line}");
}

/// A command line clap does not run: the help or version asked for, to stdout (exit 0, or 1 when
/// it cannot be written), or why the line is wrong, one line on stderr with exit 2 as for any bad
/// input (clap's own message spans five lines: the fault, a tip, the usage and a pointer to
/// `--help`; found from outside).
fn not_run(error: &clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    match error.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            let mut stdout = std::io::stdout().lock();
            let written = write!(stdout, "{error}").and_then(|()| stdout.flush());
            match stdout_written(written) {
                Err(error) => {
                    stderr_line(format_args!("{error}"));
                    error.exit_code()
                }
                Ok(()) => ExitCode::SUCCESS,
            }
        }
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            stderr_line(format_args!(
                "no command given: `bouncewear --help` lists them"
            ));
            ExitCode::from(2)
        }
        _ => {
            let text = error.to_string();
            let mut line = String::new();
            let parts = text
                .lines()
                .map(str::trim)
                .filter(|part| !part.is_empty() && !part.starts_with("For more information"));
            for part in parts {
                if !line.is_empty() {
                    line.push_str(if line.ends_with(':') { " " } else { "; " });
                }
                line.push_str(part.strip_prefix("error: ").unwrap_or(part));
            }
            stderr_line(format_args!("{} (--help for more)", one_line(&line)));
            ExitCode::from(2)
        }
    }
}

pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(error) => return not_run(&error),
    };
    let log_format = cli.log_format;
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            if let CliError::Ended { job, .. } = &error {
                // The job as it ended goes where a success would have gone; its reason to stderr.
                let _ = print_text(job.clone());
            }
            match log_format {
                LogFormat::Text => stderr_line(format_args!("{}", one_line(&error.to_string()))),
                // Every line on stderr one JSON object, the last one too.
                LogFormat::Json => tracing::error!(exit_code = error.code(), "{error}"),
            }
            error.exit_code()
        }
    }
}

fn run(cli: Cli) -> Result<(), CliError> {
    telemetry::init_logging(cli.log_format);
    // An empty `BOUNCEWEAR_KERNEL=` is no choice, as an unset one.
    if let Some(name) = cli.kernel.as_deref().filter(|name| !name.is_empty()) {
        choose_kernel(name)?;
    }
    match cli.command {
        Command::Simulate { fidelity, file } => {
            let scenario = Scenario::from_json(&read_input(&file)?)?;
            print_json(&simulate(&scenario, fidelity.into()))
        }
        Command::Calibrate {
            file,
            plot,
            observations,
        } => calibrate_command(&file, plot.as_deref(), observations.as_deref()),
        Command::Run {
            file,
            threads,
            plots,
            quiet,
        } => run_command(&file, threads, plots.as_deref(), quiet),
        Command::Serve(config) => Ok(async_runtime()?.block_on(crate::app::serve(config))?),
        Command::Worker(config) => Ok(async_runtime()?.block_on(crate::app::work(config))?),
        Command::Health {
            url,
            timeout_seconds,
        } => {
            let body = check_health(&url, timeout_seconds)?;
            print_line(&body)
        }
        Command::Submit {
            file,
            wait,
            timeout_seconds,
            server,
        } => print_text(remote::submit(&server, &file, wait, timeout_seconds)?),
        Command::Status { id, server } => print_text(remote::status(&server, &id)?),
        Command::Wait {
            id,
            timeout_seconds,
            server,
        } => print_text(remote::wait_for(&server, &id, timeout_seconds)?),
        Command::Fetch {
            id,
            part,
            csv,
            server,
        } => print_text(remote::fetch(&server, &id, part, csv)?),
        Command::Compare {
            a,
            b,
            metric,
            statistics,
            b_lives,
            plots,
            server,
        } => {
            let made = match &plots {
                Some(dir) => Some((dir.as_path(), output_directory("--plots", dir)?)),
                None => None,
            };
            let asked = remote::Compared {
                metric,
                statistics,
                b_lives,
            };
            let compared = remote::compare(&server, [&a, &b], &asked, plots.as_deref());
            print_text(unless_failed(compared, made)?)
        }
        Command::Cancel { id, server } => print_text(remote::cancel(&server, &id)?),
        Command::Schedule { command, server } => match remote::schedule(&server, &command)? {
            // A delete answers 204 with nothing to print.
            text if text.is_empty() => Ok(()),
            text => print_text(text),
        },
        Command::Bench {
            quick,
            out,
            coverage_seeds,
            only,
            threads,
            quiet,
        } => bench_command(&out, quick, coverage_seeds, only, threads, quiet),
    }
}

/// `bouncewear bench`: the report written into `out` and printed as JSON.
fn bench_command(
    out: &Path,
    quick: bool,
    coverage_seeds: Option<u32>,
    only: Option<bench::Only>,
    threads: Option<usize>,
    quiet: bool,
) -> Result<(), CliError> {
    let pool = thread_pool(threads)?;
    let earlier = only
        .map(|only| bench::read_report(out, quick).map(|report| (only, report)))
        .transpose()?;
    output_directory("--out", out)?;
    let progress = Progress::steps(quiet, bench::measurements(quick, only));
    let report = pool.install(|| match earlier {
        None => bench::bench(out, quick, coverage_seeds, &progress),
        Some((only, report)) => bench::measure_again(report, only, out, coverage_seeds, &progress),
    });
    progress.finish();
    let report = report?;
    if !quiet {
        stderr_line(format_args!(
            "wrote {}/report.{{json,md,svg}}",
            out.display()
        ));
    }
    print_json(&report)
}

/// `bouncewear calibrate`: the fit of `file` (with the measurements of the CSV `observations`,
/// if given) as JSON, and its plot written to `plot`.
fn calibrate_command(
    file: &Path,
    plot: Option<&Path>,
    observations: Option<&Path>,
) -> Result<(), CliError> {
    let mut text = read_input(file)?;
    let mut rows = None;
    if let Some(csv) = observations {
        let (request, lines) =
            with_observations(&text, &read_input(csv)?, &csv.display().to_string())?;
        (text, rows) = (request, Some(lines));
    }
    let located = |error| match &rows {
        Some(rows) => rows.locate(error),
        None => error,
    };
    let spec = CalibrationSpec::from_json(&text).map_err(located)?;
    let fit = calibrate(&spec).map_err(located)?;
    // The fit first, as `run` prints its Result first: a plot that cannot be written loses it not.
    print_json(&fit)?;
    if let Some(path) = plot {
        let svg = crate::plots::calibration_svg(&crate::plots::calibration_panels(&spec, &fit));
        std::fs::write(path, svg).map_err(|source| CliError::Write {
            path: path.display().to_string(),
            source,
        })?;
    }
    Ok(())
}

/// `bouncewear run`: the job of `file` on `threads` compute threads, its Result as JSON and its
/// plots written into `plots`.
fn run_command(
    file: &Path,
    threads: Option<usize>,
    plots: Option<&Path>,
    quiet: bool,
) -> Result<(), CliError> {
    // The Result printed lists no device's own life: none is kept.
    let job = Job::from_json(&read_input(file)?, draw_seed)?.with_listed_lives(0);
    check_threshold(&job, &Pointer::root().child("rare_event"))?;
    let pool = thread_pool(threads)?;
    let made = match plots {
        Some(dir) => Some((dir, output_directory("--plots", dir)?)),
        None => None,
    };
    let progress = Progress::operations(quiet);
    let result = pool.install(|| run_job(&job, &progress));
    progress.finish();
    let result = result.map_err(|cancelled| CliError::Failed(cancelled.to_string()));
    let result = unless_failed(result, made)?;
    // The Result first: plots that cannot be written then lose nothing of the run.
    print_json(&result)?;
    match plots {
        Some(dir) => write_plots(&result, dir),
        None => Ok(()),
    }
}

/// The body of a 200 from `url`; anything else is a failure naming what went wrong.
fn check_health(url: &str, timeout_seconds: f64) -> Result<String, CliError> {
    let agent = remote::agent(timeout_seconds, None);
    let url = &health_url(url);
    let shown = crate::config::shown_url(url);
    remote::check_base_url(url).map_err(|rule| {
        CliError::Usage(format!("--url (BOUNCEWEAR_HEALTH_URL) {shown}: {rule}"))
    })?;
    let unhealthy = |what: String| CliError::Failed(format!("{shown}: {what}"));
    let mut response = agent
        .get(url)
        .call()
        .map_err(|e| unhealthy(e.to_string()))?;
    let body = response
        .body_mut()
        .read_to_string()
        .map_err(|e| unhealthy(e.to_string()))?;
    match response.status().as_u16() {
        200 => Ok(body),
        status => Err(unhealthy(format!("{status} {body}"))),
    }
}

/// The URL `health` asks: `url` where its path ends in `/healthz` or `/readyz`, else a server's
/// address (`http://host:8080`, `http://proxy/bouncewear`, as `--url` is given to the remote
/// commands) with `/healthz` added. Asked as it was, such an address answered the dashboard's
/// page, 200, and the check passed printing its HTML.
fn health_url(url: &str) -> String {
    let path = url.split(['?', '#']).next().unwrap_or_default();
    if path.ends_with("/healthz") || path.ends_with("/readyz") {
        url.to_owned()
    } else {
        format!("{}/healthz", url.trim_end_matches('/'))
    }
}

/// The dashboard's plots of a result, as SVG files.
fn write_plots(
    result: &bouncewear_model::montecarlo::JobResult,
    dir: &std::path::Path,
) -> Result<(), CliError> {
    let io = |path: &std::path::Path| {
        let path = path.display().to_string();
        move |source| CliError::Write { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut files = Vec::new();
    for metric in result.operations.keys() {
        for kind in ["bands", "histograms"] {
            let svg = crate::plots::job_plot(result, &format!("{kind}.svg"), metric)
                .map_err(|e| CliError::Failed(e.to_string()))?;
            files.push((format!("{kind}-{metric}.svg"), svg));
        }
    }
    if let Some(life) = &result.life {
        files.push((
            "weibull.svg".to_owned(),
            crate::plots::weibull_svg(&life.analysis),
        ));
    }
    for (metric, bins) in result.sensitivity.iter().flatten() {
        files.push((
            format!("sensitivity-{metric}.svg"),
            crate::plots::sensitivity_svg(metric, bins),
        ));
    }
    if result.rare_event.is_some() {
        let svg = crate::plots::job_plot(result, "tail.svg", "")
            .map_err(|e| CliError::Failed(e.to_string()))?;
        files.push(("tail.svg".to_owned(), svg));
    }
    for (name, svg) in files {
        let path = dir.join(name);
        std::fs::write(&path, svg).map_err(io(&path))?;
    }
    Ok(())
}

/// The runtime `serve` and `worker` run on; compute has its own pool.
fn async_runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("bouncewear-async")
        .build()
        .map_err(|e| CliError::Failed(format!("cannot start the async runtime: {e}")))
}

/// A rayon pool of `threads` workers (all cores by default).
fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, CliError> {
    Ok(crate::compute::thread_pool(threads)?)
}

/// Reads a file, or standard input for `-`.
pub fn read_input(path: &Path) -> Result<String, CliError> {
    let io = |source| CliError::Io {
        path: path.display().to_string(),
        source,
    };
    let mut bytes = Vec::new();
    let limit = MAX_INPUT_BYTES as u64 + 1;
    if path.as_os_str() == "-" {
        std::io::stdin().lock().take(limit).read_to_end(&mut bytes)
    } else {
        std::fs::File::open(path).and_then(|file| file.take(limit).read_to_end(&mut bytes))
    }
    .map_err(io)?;
    if bytes.len() > MAX_INPUT_BYTES {
        return Err(CliError::Usage(format!(
            "{}: more than {} MB; a job, scenario or calibration request is far smaller",
            path.display(),
            MAX_INPUT_BYTES >> 20
        )));
    }
    // A byte-order mark (a spreadsheet's "CSV UTF-8", some editors' JSON) is not part of the text.
    if bytes.starts_with(b"\xef\xbb\xbf") {
        bytes.drain(..3);
    }
    String::from_utf8(bytes).map_err(|error| {
        let at = error.utf8_error().valid_up_to();
        let byte = error.as_bytes()[at];
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text: the byte at offset {at} ({byte:#04x}) starts no UTF-8 character"
            ),
        ))
    })
}

/// The largest input [`read_input`] reads: `/dev/zero` took 9.4 GB in ten seconds before (found
/// from outside), where the server takes 1 MB a request by default.
pub const MAX_INPUT_BYTES: usize = 64 << 20;

/// The calibration request `text` with its `observations` read from CSV `csv` (at `path`), and
/// the line of each.
fn with_observations(
    text: &str,
    csv: &str,
    path: &str,
) -> Result<(String, measurements::RowLines), CliError> {
    let mut request: serde_json::Value = serde_json::from_str(text).map_err(|error| {
        CliError::Invalid(InvalidInput::single(
            &Pointer::root(),
            format!("the request is not JSON: {error}"),
        ))
    })?;
    let object = request.as_object_mut().ok_or_else(|| {
        CliError::Invalid(InvalidInput::single(
            &Pointer::root(),
            "a calibration request is a JSON object",
        ))
    })?;
    // Two lists of observations are one too many: the file's were dropped without a word
    // (found from outside).
    if object.contains_key("observations") {
        return Err(CliError::Usage(format!(
            "--observations {path}: the request has `observations` too; give them in one place"
        )));
    }
    let (rows, lines) = measurements::observations_from_csv(csv, path)?;
    object.insert("observations".to_owned(), rows);
    Ok((request.to_string(), lines))
}

/// A server's answer on stdout: JSON as `print_json` writes it (a Result field for field as `run`
/// prints it), anything else (CSV) as it came.
fn print_text(text: String) -> Result<(), CliError> {
    if let Ok(result) = serde_json::from_str::<bouncewear_model::montecarlo::JobResult>(&text) {
        return print_json(&result);
    }
    if let Ok(value) = serde_json::from_str::<serde_json::Value>(&text) {
        return print_json(&value);
    }
    print_line(&text)
}

/// `text` and a newline on stdout, as [`print_json`] writes (a reader gone is not an error).
fn print_line(text: &str) -> Result<(), CliError> {
    let mut out = std::io::stdout().lock();
    stdout_written(writeln!(out, "{text}").and_then(|()| out.flush()))
}

/// Prints a document to stdout, buffered (a Result is thousands of lines). A reader that stops
/// early (`| head`) is not an error: the output simply ends there.
fn print_json(value: &impl serde::Serialize) -> Result<(), CliError> {
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let written = serde_json::to_writer_pretty(&mut out, value)
        .map_err(std::io::Error::from)
        .and_then(|()| writeln!(out))
        .and_then(|()| out.flush());
    stdout_written(written)
}

/// What writing to stdout came to: a reader that stopped early (`| head`) is not an error, the
/// output simply ends there; any other failure (a full disk) is.
fn stdout_written(written: std::io::Result<()>) -> Result<(), CliError> {
    match written {
        Err(error) if error.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        written => written.map_err(|source| CliError::Write {
            path: "<stdout>".into(),
            source,
        }),
    }
}

//! The `progmo` command line: compute programmed motions from scene files. One implementation for
//! both doors: the `progmo` binary (src/main.rs) and the `progmo` command of the Python package
//! (which calls [`run`] through the binding and handles check/debug/bench/report itself).
//!
//! Exit codes (stable; scripts and the nightly check branch on them):
//! - 0: success;
//! - 1: the solve stopped early with a non-success return code (what was computed is written);
//! - 2: bad input: the scene file (or the command line) is invalid, or its initial state is off
//!   the programme;
//! - 3: the results could not be written (including standard output on a full device);
//! - 130: interrupted (Ctrl-C or SIGTERM during `solve`: the files are finished as partial results);
//! - 141: standard output was closed early (`| head -1`): the command ends quietly.

use crate::output::{
    write_summary_to_path, OutputSink, Progress, RunFiles, SampleLayout, StopOn, SummaryInput,
};
use crate::scene::{Scene, SceneError};
use crate::solve::{OverrideError, Overrides, ReturnCode, Settings};
use clap::{Parser, Subcommand, ValueEnum};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::GIT_REVISION;

/// `eprintln!` that never panics (a diagnostic that cannot be written has nowhere else to go).
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// Write a line to standard output without ever panicking: a closed pipe (`| head -1`) ends the
/// command quietly with status 141 (as a tool killed by SIGPIPE), any other failure (a full device)
/// is reported on stderr with exit code 3.
fn write_stdout(args: std::fmt::Arguments<'_>, newline: bool) -> Result<(), ExitCode> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    let r = o
        .write_fmt(args)
        .and_then(|_| if newline { o.write_all(b"\n") } else { Ok(()) })
        .and_then(|_| o.flush());
    match r {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(ExitCode::from(141)),
        Err(e) => {
            errln!("progmo: error: cannot write to standard output: {e}");
            Err(ExitCode::from(3))
        }
    }
}

/// `println!` that returns the exit code of [`write_stdout`] from the enclosing function on failure.
macro_rules! say {
    ($($arg:tt)*) => {
        if let Err(code) = write_stdout(format_args!($($arg)*), true) {
            return code;
        }
    };
}

#[derive(Parser)]
#[command(
    name = "progmo",
    version,
    about = "Programmed motions of mechanical systems (Do Sanh 1998): motion and control forces from a scene file",
    after_help = "Exit codes: 0 success, 1 solve stopped early (partial results written), 2 bad input, 3 cannot write results, 130 interrupted.\nScene format: src/scene/FORMAT.md. A bundled scene is named without a path: `progmo solve double_pendulum`."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Solve a scene: writes trajectory.csv, summary.json and recording.mcap into the output folder.
    Solve(Box<SolveArgs>),
    /// Check scenes without solving: parse, dimensions, consistency of the initial state.
    Validate {
        /// Scene files (TOML) or names of bundled scenes.
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
        /// Print one JSON array on stdout (one object per scene) instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Export a tree scene's model to MJCF (MuJoCo) or URDF (Pinocchio), with a JSON report of what
    /// the simulator must be told besides (mass floors, forces the harness applies, q/v maps).
    Export {
        /// Scene file (TOML) or name of a bundled scene.
        scene: PathBuf,
        /// Target format.
        #[arg(long, value_enum)]
        format: FormatArg,
        /// Output file [default: standard output]; the report goes to <out>.report.json.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print one JSON object on stdout: format, the document (or its path with --out), report.
        #[arg(long)]
        json: bool,
    },
    /// The nightly cross-simulator check (Python harness): replay u(t) in MuJoCo and Pinocchio,
    /// judge against the scenes' budgets and baselines, write the report. `progmo check --help`.
    #[command(disable_help_flag = true)]
    Check {
        /// Arguments for the harness (scenes, --accept, --jobs, --out, --help).
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Speed against error (Python harness): work-precision diagrams, the scipy + Pinocchio pipeline,
    /// the paper's conditioning claim, right-hand-side scaling. `progmo bench --help`.
    #[command(disable_help_flag = true)]
    Bench {
        /// Arguments for the harness.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Import the robot files of public collections (example-robot-data, gymnasium, dm_control,
    /// MuJoCo Menagerie) and compare A and G + Q with MuJoCo's and Pinocchio's reading of each
    /// (Python harness). `progmo corpus --help`.
    #[command(disable_help_flag = true)]
    Corpus {
        /// Arguments for the harness.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Tolerance report over distributions of runs (Python harness): parameters, initial states
    /// and solver settings drawn from a sweep file, each sample checked in the simulators, on this
    /// machine or a Ray cluster. `progmo sweep --help`.
    #[command(disable_help_flag = true)]
    Sweep {
        /// Arguments for the harness.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Re-render the report of a saved check run from its results.json (Python harness).
    /// `progmo report --help`.
    #[command(disable_help_flag = true)]
    Report {
        /// Arguments for the harness.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// A debugging run of one scene (Python harness): MCAP with solver and simulator channels, CSV,
    /// the first tolerance breach. `progmo debug --help`.
    #[command(disable_help_flag = true)]
    Debug {
        /// Arguments for the harness.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Mjcf,
    Urdf,
}

#[derive(clap::Args)]
struct SolveArgs {
    /// Scene file (TOML) or name of a bundled scene (`progmo solve double_pendulum`).
    scene: PathBuf,
    /// Output folder [default: out/<scene name>].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Settings: each overrides the scene file's key of the same name (`progmo::solve::Overrides`,
    /// the one definition shared with the scene file and `Scene.solve`).
    #[command(
        flatten,
        next_help_heading = "Settings (override the scene file's keys of the same name)"
    )]
    settings: Overrides,
    /// Do not write the MCAP recording.
    #[arg(long)]
    no_mcap: bool,
    /// Never show a progress bar (it is shown only on a terminal anyway).
    #[arg(long)]
    quiet: bool,
    /// Print the run's summary (summary.json's content and the output folder) as JSON on stdout;
    /// the one-line report goes to stderr.
    #[arg(long)]
    json: bool,
}

/// The exit status of a command (the codes above).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExitCode(pub u8);

impl ExitCode {
    pub const SUCCESS: Self = Self(0);
    pub fn from(code: u8) -> Self {
        Self(code)
    }
}

/// Every long flag of `progmo solve` (`tests/schema.rs` checks that those other than the run's own
/// options are the settings of [`crate::solve::settings`], the names of the scene file's keys).
pub fn solve_flags() -> Vec<String> {
    use clap::CommandFactory;
    let cli = Cli::command();
    let solve = cli
        .find_subcommand("solve")
        .expect("progmo has a solve command");
    solve
        .get_arguments()
        .filter_map(|a| a.get_long())
        .map(str::to_string)
        .collect()
}

/// Run the command line `args` (the first item is the program name); returns the exit code.
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    dispatch(args).0
}

fn dispatch<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let args: Vec<std::ffi::OsString> = args.into_iter().map(Into::into).collect();
    // As the OS gave them (a non-UTF-8 path must not stop the run after the solve).
    let line: Vec<String> = args
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => return usage(e),
    };
    match cli.command {
        Command::Solve(a) => solve(*a, &line),
        Command::Validate { scenes, json } => validate(&scenes, json),
        Command::Export {
            scene,
            format,
            out,
            json,
        } => export(&scene, format, out.as_deref(), json),
        Command::Check { args } => harness("check", &["-m", "progmo.cli", "check"], &args),
        Command::Debug { args } => harness("debug", &["-m", "progmo.cli", "debug"], &args),
        Command::Bench { args } => harness("bench", &["-m", "progmo.bench.main"], &args),
        Command::Corpus { args } => harness("corpus", &["-m", "progmo.corpus"], &args),
        Command::Report { args } => harness("report", &["-m", "progmo.cli", "report"], &args),
        Command::Sweep { args } => harness("sweep", &["-m", "progmo.sweep"], &args),
    }
}

/// The checkout this binary runs from, found at run time (`<root>/target/<profile>/progmo`; no
/// path is baked in at build time): where a developer's `cargo build` leaves it beside the
/// harness's `.venv` and the bundled references. None for a binary elsewhere (an installed one,
/// or the Python package's in-process CLI, which sets `$PROGMO_REFERENCES` instead).
fn checkout_root() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let root = exe.parent()?.parent()?.parent()?;
    (exe.parent()?.parent()?.file_name()? == "target" && root.join("Cargo.toml").is_file())
        .then(|| root.to_path_buf())
}

/// The harness's Python: $PROGMO_PYTHON, else the `.venv` of the checkout this binary runs from.
fn harness_python() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("PROGMO_PYTHON") {
        return Some(PathBuf::from(p));
    }
    checkout_root()
        .map(|r| r.join(".venv/bin/python"))
        .filter(|p| p.exists())
}

/// A command line clap refused, or `--help` / `--version`: help goes to standard output (exit 0,
/// or 3 if it cannot be written: nothing is lost silently), a usage error to stderr (exit 2).
fn usage(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            let text = e.render().to_string();
            match write_stdout(format_args!("{}", text.trim_end()), true) {
                Ok(()) => ExitCode::SUCCESS,
                Err(code) => code,
            }
        }
        _ => {
            let text = e.render();
            let text = if std::io::stderr().is_terminal() {
                text.ansi().to_string()
            } else {
                text.to_string()
            };
            errln!("{}", text.trim_end());
            ExitCode::from(2)
        }
    }
}

fn harness(sub: &str, module: &[&str], args: &[String]) -> ExitCode {
    let Some(python) = harness_python() else {
        errln!(
            "progmo {sub}: error: the Python harness is not set up (no .venv found); run `bash harness/setup.sh` once, or set PROGMO_PYTHON"
        );
        return ExitCode::from(2);
    };
    let status = std::process::Command::new(&python)
        .args(module)
        .args(args)
        .status();
    match status {
        Ok(s) => ExitCode::from(s.code().unwrap_or(1).clamp(0, 255) as u8),
        Err(e) => {
            errln!("progmo {sub}: error: cannot run {}: {e}", python.display());
            ExitCode::from(2)
        }
    }
}

/// Where bundled scenes are looked for, by the rule `progmo.data.scene_file` follows in Python:
/// `$PROGMO_REFERENCES/scenes` when it is set (the Python package sets it to the references it
/// ships; a project points it at its own catalog), and then nowhere else; otherwise the
/// references of the checkout this binary runs from.
fn bundled_scene_dir() -> Option<PathBuf> {
    match std::env::var_os("PROGMO_REFERENCES") {
        Some(r) => Some(PathBuf::from(r).join("scenes")),
        None => checkout_root().map(|r| r.join("references/scenes")),
    }
}

/// A scene argument: a file as given, else the name of a bundled scene (`double_pendulum`, with
/// or without `.toml`); the same rule as `progmo.data.scene_file` in Python.
fn scene_file(arg: &Path) -> Result<PathBuf, String> {
    let bare = arg.parent().is_none_or(|p| p.as_os_str().is_empty())
        && arg.extension().is_none_or(|e| e == "toml");
    // a FIFO, device or folder given as a path: the core refuses it by what it is (src/input.rs)
    if arg.exists() && !(bare && arg.is_dir()) {
        return Ok(arg.to_path_buf());
    }
    if !bare {
        return Err(format!("{}: no such scene file", arg.display()));
    }
    let stem = arg.file_stem().unwrap_or_default();
    let Some(dir) = bundled_scene_dir() else {
        return Err(format!(
            "{}: no such scene file, and no bundled scenes to look in (set PROGMO_REFERENCES to a \
             references folder, or run the Python package's `progmo`)",
            arg.display()
        ));
    };
    let f = dir.join(stem).with_extension("toml");
    if f.is_file() {
        return Ok(f);
    }
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let p = e.path();
            if p.extension()? != "toml" {
                return None;
            }
            Some(p.file_stem()?.to_string_lossy().into_owned())
        })
        .collect();
    names.sort();
    Err(format!(
        "{}: no such scene file or bundled scene (bundled in {}: {})",
        arg.display(),
        dir.display(),
        if names.is_empty() {
            "none found".to_string()
        } else {
            names.join(", ")
        }
    ))
}

fn load(arg: &Path) -> Result<Scene, ExitCode> {
    let path = scene_file(arg).map_err(|e| {
        errln!("progmo: error: {e}");
        ExitCode::from(2)
    })?;
    Scene::load(&path).map_err(|e: SceneError| {
        errln!("{e}");
        ExitCode::from(2)
    })
}

/// One JSON value on standard output (the `--json` of every subcommand).
fn say_json(v: &serde_json::Value) -> Result<(), ExitCode> {
    let text =
        serde_json::to_string_pretty(v).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    write_stdout(format_args!("{text}"), true)
}

fn settings_from(a: &SolveArgs, base: &Settings) -> Result<Settings, String> {
    // The flags are the one definition's overrides (ranges checked here, names by clap); the
    // values' consistency with the span is checked by `solve::validate`, which names the flag.
    a.settings.check().map_err(|e| {
        let value = a.settings.to_table().get(&e.name).map(ToString::to_string);
        let flag = e.name.replace('_', "-");
        format!("--{flag} {}: {}", value.unwrap_or_default(), e.message)
    })?;
    base.apply(&a.settings).map_err(|e| match e {
        OverrideError::StepRequired => "--integrator rk4 needs --step".to_string(),
        e => format!("--{}: {e}", e.field()),
    })
}

/// A settings error named by the flag that set the value (`--t1 inf: ...`), else by its scene key.
fn flagged(a: &SolveArgs, e: &crate::solve::SettingsError) -> String {
    let name = e.field.name();
    if a.settings.has(name) {
        format!("--{} {:?}: {}", name.replace('_', "-"), e.value, e.message)
    } else {
        format!("{}: {}", a.scene.display(), e)
    }
}

/// A refused solve clears the earlier run's outputs from its folder (when the folder exists), as a
/// started run does: nothing of that run (a summary saying success) may pass for this one's.
fn clear_earlier_run(out: Option<&Path>) {
    if let Some(dir) = out.filter(|d| d.is_dir()) {
        if let Err(e) = crate::output::remove_previous_run(dir) {
            errln!("progmo solve: error: {e}");
        }
    }
}

fn solve(a: SolveArgs, command_line: &[String]) -> ExitCode {
    let mut scene = match load(&a.scene) {
        Ok(s) => s,
        Err(c) => {
            clear_earlier_run(a.out.as_deref());
            return c;
        }
    };
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&scene.name));
    let settings = match solve_settings(&a, &mut scene, &out) {
        Ok(s) => s,
        Err(code) => return code,
    };
    if let Err(code) = prepare_output(&scene, &out) {
        return code;
    }
    let layout = crate::with_problem!(&scene.system, p => SampleLayout::from_problem(p));
    let (t0, t1) = scene.span();
    // trajectory.csv and recording.mcap get their names only when whole (`.partial` until then).
    let files = match RunFiles::create(&out, &layout, !a.no_mcap, scene.bodies()) {
        Ok(f) => f,
        Err(e) => {
            errln!("progmo solve: error: {e}");
            return ExitCode::from(3);
        }
    };
    // Ctrl-C / SIGTERM stop the solve at the next step; the files are finished as partial.
    let interrupt = crate::interrupt::Guard::install();
    let show = !a.quiet && std::io::stderr().is_terminal();
    let started = Instant::now();
    let mut sink =
        Progress::new(StopOn::new(files, interrupt.flag()), &scene.name, t0, t1).enabled(show);
    let solution = scene.solve_into(&settings, &mut sink);
    let _ = sink.finish(); // the errors of every file are collected next
    let mut write_errors = sink.into_inner().into_inner().errors();
    let wall = started.elapsed().as_secs_f64();
    let rows = layout.row_names.clone();
    let run = FinishedRun {
        scene: &scene,
        solution: &solution,
        settings: &settings,
        out: &out,
        t0,
        wall,
    };
    let json = run.write_summary(&a, &rows, command_line, &mut write_errors);
    if let Err(code) = run.report(json.as_ref()) {
        return code;
    }
    // A file that could not be written is the last word (exit 3), whatever the solve did.
    for e in &write_errors {
        errln!("progmo solve: error: cannot write the results: {e}");
    }
    match &solution.code {
        _ if !write_errors.is_empty() => ExitCode::from(3),
        ReturnCode::Success => ExitCode::SUCCESS,
        ReturnCode::Interrupted { .. } => ExitCode::from(130),
        _ => ExitCode::from(1),
    }
}

/// The settings of a solve (the scene's, overridden by the flags) and the span set by `--t1`,
/// checked; a refusal clears the earlier run's outputs in `out`.
fn solve_settings(a: &SolveArgs, scene: &mut Scene, out: &Path) -> Result<Settings, ExitCode> {
    let refused = |msg: std::fmt::Arguments<'_>| {
        errln!("progmo solve: error: {msg}");
        clear_earlier_run(Some(out));
        ExitCode::from(2)
    };
    let settings = match settings_from(a, &scene.settings) {
        Ok(s) => s,
        Err(msg) => return Err(refused(format_args!("{msg}"))),
    };
    if let Some(t1) = a.settings.t1 {
        let (t0, _) = scene.span();
        if !(t1 > t0) {
            return Err(refused(format_args!("--t1 {t1} must be after t0 = {t0}")));
        }
        crate::with_problem!(&mut scene.system, p => p.t1 = t1);
    }
    if let Err(e) = crate::solve::validate(scene.span(), &settings) {
        return Err(refused(format_args!("{}", flagged(a, &e))));
    }
    Ok(settings)
}

/// The notes on the scene's import, then the output folder, emptied of an earlier run.
fn prepare_output(scene: &Scene, out: &Path) -> Result<(), ExitCode> {
    for n in &scene.import_notes {
        errln!("progmo solve: note: {n}");
    }
    for line in unmodelled_lines(scene) {
        errln!("progmo solve: {line}");
    }
    if let Err(e) = std::fs::create_dir_all(out) {
        errln!("progmo solve: error: cannot create {}: {e}", out.display());
        return Err(ExitCode::from(3));
    }
    // A run into the folder of an earlier one first removes that run's outputs, so nothing of it
    // (an old summary saying success, an MCAP of another scene) can pass for this run's.
    if let Err(e) = crate::output::remove_previous_run(out) {
        errln!("progmo solve: error: {e}");
        return Err(ExitCode::from(3));
    }
    Ok(())
}

/// A solve that has run: what its summary and its report line are made of.
struct FinishedRun<'a> {
    scene: &'a Scene,
    solution: &'a crate::solve::Solution,
    settings: &'a Settings,
    out: &'a Path,
    t0: f64,
    wall: f64,
}

impl FinishedRun<'_> {
    /// Write summary.json (partial beside a partial data file; its error joins `write_errors`);
    /// with `--json`, the summary's content and the output folder for stdout.
    fn write_summary(
        &self,
        a: &SolveArgs,
        rows: &[String],
        command_line: &[String],
        write_errors: &mut Vec<crate::output::OutputError>,
    ) -> Option<serde_json::Value> {
        let (scene, settings) = (self.scene, self.settings);
        // Servo scenes: the analysis with the internal dynamics along the motion (two more solves).
        let servo = scene
            .servo_report(settings, true)
            .and_then(|r| serde_json::to_value(r).ok());
        let robot_file = scene
            .robot
            .as_ref()
            .and_then(|r| serde_json::to_value(r).ok());
        let summary = SummaryInput {
            scene: &scene.name,
            solution: self.solution,
            row_names: rows,
            settings,
            wall_seconds: self.wall,
            git_revision: (!GIT_REVISION.is_empty()).then_some(GIT_REVISION),
            command_line,
            servo: servo.as_ref(),
            robot_file: robot_file.as_ref(),
        };
        // Beside a data file that could not be written whole (a `.partial`), the summary is partial
        // too: a summary.json saying success must mean the run's files are whole.
        let summary_name = if write_errors.is_empty() {
            "summary.json"
        } else {
            "summary.json.partial"
        };
        write_errors.extend(write_summary_to_path(self.out.join(summary_name), &summary).err());
        // --json: the summary's content (and where the files are) on stdout, the line on stderr.
        a.json.then(|| {
            let mut v = crate::output::summary_json(&summary).unwrap_or(serde_json::Value::Null);
            if let Some(m) = v.as_object_mut() {
                m.insert("output".into(), self.out.display().to_string().into());
            }
            v
        })
    }

    /// The warnings and the line that says how the solve ended (on stdout, or on stderr with the
    /// JSON document on stdout); an inconsistent or singular initial state is a located error.
    fn report(&self, json: Option<&serde_json::Value>) -> Result<(), ExitCode> {
        let (scene, solution, out, t0) = (self.scene, self.solution, self.out, self.t0);
        let report = |line: std::fmt::Arguments<'_>| -> Result<(), ExitCode> {
            match json {
                Some(v) => {
                    errln!("{line}");
                    say_json(v)
                }
                None => write_stdout(line, true),
            }
        };
        let worst = solution.max_residual.iter().cloned().fold(0.0, f64::max);
        let st = &solution.stats.integrator;
        for w in &solution.warnings {
            errln!("{}: warning: {w}", scene.name);
        }
        let warned = match solution.warnings.len() {
            0 => String::new(),
            1 => format!(
                ", 1 conditioning WARNING ({} at t = {:.6})",
                solution.warnings[0].kind.name(),
                solution.warnings[0].t
            ),
            k => format!(
                ", {k} conditioning WARNINGS (first: {} at t = {:.6})",
                solution.warnings[0].kind.name(),
                solution.warnings[0].t
            ),
        };
        match &solution.code {
            ReturnCode::Success => report(format_args!(
                "{}: success, t = {:.6} .. {:.6}, max programme residual {:.2e}, {} steps ({} rejected), {} RHS evaluations, {:.3} s{warned} -> {}",
                scene.name, t0, solution.t_end, worst, st.steps, st.rejected, st.rhs_evals, self.wall, out.display()
            )),
            code if solution.stats.integrator.steps == 0
                && solution.t_end == t0
                && matches!(
                    code,
                    ReturnCode::InconsistentInitialState { .. }
                        | ReturnCode::SingularProgramme { .. }
                        | ReturnCode::UnrealizableProgramme { .. }
                ) =>
            {
                errln!("{}", scene.initial_error(code, self.settings));
                Err(ExitCode::from(2))
            }
            code => {
                errln!(
                    "{}: stopped at t = {:.6} ({}): {code}; results up to there are in {}",
                    scene.name,
                    solution.t_end,
                    code.name(),
                    out.display()
                );
                report(format_args!(
                    "{}: {}, t = {:.6} .. {:.6}, max programme residual {:.2e}{warned} -> {}",
                    scene.name,
                    code.name(),
                    t0,
                    solution.t_end,
                    worst,
                    out.display()
                ))
            }
        }
    }
}

/// One line per element of the robot file that is not modelled: `not modelled (declared: REASON)`
/// or `not modelled, undeclared` with kind, element and location.
fn unmodelled_lines(scene: &Scene) -> Vec<String> {
    scene
        .robot
        .iter()
        .flat_map(|r| &r.unmodelled)
        .map(|u| match &u.declared {
            Some(reason) => format!(
                "not modelled ({}, declared ignorable: {reason}): {} at {}",
                u.kind, u.element, u.location
            ),
            None => format!(
                "not modelled ({}, UNDECLARED: the check reports it as not checked): {} at {}",
                u.kind, u.element, u.location
            ),
        })
        .collect()
}

#[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
fn validate(scenes: &[PathBuf], json: bool) -> ExitCode {
    let mut failed = false;
    let mut objects = vec![];
    for path in scenes {
        let scene = match load(path) {
            Ok(s) => s,
            Err(_) => {
                failed = true;
                objects.push(serde_json::json!({
                    "scene": path.display().to_string(), "ok": false, "error": "does not load (see stderr)"
                }));
                continue;
            }
        };
        let rows = scene.rows();
        match scene.check_initial(&scene.settings) {
            Ok((traj, corr)) if json => {
                let res = traj.residual_at(0);
                objects.push(serde_json::json!({
                    "scene": path.display().to_string(),
                    "name": scene.name,
                    "ok": true,
                    "nq": scene.q_names().len(),
                    "nv": scene.v_names().len(),
                    "t0": scene.span().0,
                    "t1": scene.span().1,
                    "rows": rows.iter().zip(res).map(|(r, x)| serde_json::json!({
                        "name": r.name, "level": format!("{:?}", r.level).to_lowercase(),
                        "role": format!("{:?}", r.role).to_lowercase(), "initial_residual": x,
                    })).collect::<Vec<_>>(),
                    "initial_correction": corr.map(|c| serde_json::json!({"position": c.position, "velocity": c.velocity})),
                    "set_aside": scene.set_aside.as_ref().map(|s| &s.0),
                    "servo": scene.servo_report(&scene.settings, false),
                    "notes": scene.import_notes,
                    "robot_file": scene.robot,
                }));
            }
            Ok((traj, corr)) => {
                let res = traj.residual_at(0);
                say!(
                    "{}: ok: nq = {}, nv = {}, {} rows ({}), t = {} .. {}",
                    scene.name,
                    scene.q_names().len(),
                    scene.v_names().len(),
                    rows.len(),
                    rows.iter()
                        .zip(res)
                        .map(|(r, x)| format!(
                            "{} {:?}/{:?} residual {x:.1e}",
                            r.name, r.level, r.role
                        ))
                        .collect::<Vec<_>>()
                        .join(", "),
                    scene.span().0,
                    scene.span().1
                );
                for r in scene.set_aside.iter().flat_map(|s| &s.0) {
                    say!("  closure row {} set aside: {}", r.row, r.reason);
                }
                if let Some(c) = corr {
                    say!(
                        "  initial state assembled: |dq| = {:.3e}, |dv| = {:.3e}",
                        c.position,
                        c.velocity
                    );
                }
                for n in &scene.import_notes {
                    say!("  note: {n}");
                }
                for line in unmodelled_lines(&scene) {
                    say!("  {line}");
                }
                if let Some(r) = scene.servo_report(&scene.settings, false) {
                    let an = &r.analysis;
                    say!(
                        "  servo-constraints: {} realization at t0, derivatives until tau appears \
                         {:?}, index {} (decoupling pivot ratio {:.2e})",
                        an.realization.name(),
                        an.differentiations,
                        an.index,
                        an.rcond
                    );
                    if let Some(red) = &an.reduction {
                        let names = |ix: &[usize]| -> Vec<&str> {
                            ix.iter().map(|&i| rows[i].name.as_str()).collect()
                        };
                        say!(
                            "  rank-deficient decoupling: kept {:?} at degree {:?}, replaced {:?} by \
                             their tau-free combinations with the kept rows (degrees {:?} more)",
                            names(&red.kept),
                            red.kept.iter().map(|&i| an.degrees[i]).collect::<Vec<_>>(),
                            names(&red.eliminated),
                            red.eliminated.iter().map(|&i| an.degrees[i]).collect::<Vec<_>>()
                        );
                    }
                    say!("  {}", r.internal_line());
                }
            }
            Err(e) => {
                failed = true;
                errln!("{e}");
                objects.push(serde_json::json!({
                    "scene": path.display().to_string(), "name": scene.name, "ok": false,
                    "error": e.to_string(),
                }));
            }
        }
    }
    if json {
        if let Err(code) = say_json(&serde_json::Value::Array(objects)) {
            return code;
        }
    }
    if failed {
        ExitCode::from(2)
    } else {
        ExitCode::SUCCESS
    }
}

fn export(path: &Path, format: FormatArg, out: Option<&Path>, json: bool) -> ExitCode {
    let scene = match load(path) {
        Ok(s) => s,
        Err(c) => return c,
    };
    let options = crate::export::ExportOptions {
        name: scene.name.clone(),
        ..Default::default()
    };
    let result = scene.export(
        match format {
            FormatArg::Mjcf => crate::export::Format::Mjcf,
            FormatArg::Urdf => crate::export::Format::Urdf,
        },
        &options,
    );
    let (doc, report) = match result {
        Ok(x) => x,
        Err(e) => {
            errln!(
                "{}: error: cannot export `{}`: {e}",
                path.display(),
                scene.name
            );
            return ExitCode::from(2);
        }
    };
    let report_value = serde_json::to_value(&report).unwrap_or(serde_json::Value::Null);
    let report_text = serde_json::to_string_pretty(&report_value).unwrap_or_default();
    let format_name = format!("{:?}", report.format).to_lowercase();
    let written = match out {
        None => None,
        Some(o) => {
            let rp = crate::output::with_suffix(o, ".report.json");
            for (file, text) in [(o, doc.as_str()), (rp.as_path(), report_text.as_str())] {
                if let Err(e) = std::fs::write(file, text) {
                    errln!("progmo export: error: cannot write {}: {e}", file.display());
                    return ExitCode::from(3);
                }
            }
            Some((o.to_path_buf(), rp))
        }
    };
    // Reports on stdout, diagnostics on stderr: the document (or the paths written) is the report;
    // --json puts everything in one object.
    let r = match (&written, json) {
        (_, true) => {
            let mut v = serde_json::json!({"scene": scene.name, "format": format_name, "report": report_value});
            match &written {
                Some((o, rp)) => {
                    v["path"] = o.display().to_string().into();
                    v["report_path"] = rp.display().to_string().into();
                }
                None => v["document"] = doc.into(),
            }
            say_json(&v)
        }
        (Some((o, rp)), false) => write_stdout(
            format_args!("wrote {} and {}", o.display(), rp.display()),
            true,
        ),
        (None, false) => {
            errln!(
                "progmo export: the report (mass floors, forces the harness applies, q/v maps) is written with --out FILE (FILE.report.json) or --json"
            );
            write_stdout(format_args!("{doc}"), false)
        }
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(code) => code,
    }
}

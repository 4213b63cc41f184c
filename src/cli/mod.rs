//! The command line: `jderobot [CONF]`, `jderobot list`, `jderobot help NAME`,
//! `jderobot check CONF`.
//!
//! [`main`] is the whole program; `src/main.rs` only calls it, and a user's own
//! crate that adds schemas calls it too.

use std::{path::PathBuf, process::ExitCode, time::Duration};

use clap::{Parser, Subcommand};

#[cfg(feature = "gui")]
mod window;

use crate::{conf::Conf, loader, registry, shell};

/// jderobot: program a robot as concurrent periodic schemas.
///
/// Runs the conf file CONF (default ./jde.conf): loads its drivers, services and
/// schemas, runs and shows what it says, then reads shell commands from standard
/// input (type `help`). Without a display, or with --headless, no GUI starts.
#[derive(Parser, Debug)]
#[command(
    name = "jderobot",
    version,
    args_conflicts_with_subcommands = true,
    disable_help_subcommand = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// The conf file to run.
    #[arg(value_name = "CONF", default_value = "jde.conf")]
    pub conf: PathBuf,
    /// Run with no GUI (automatic when there is no display).
    #[arg(long)]
    pub headless: bool,
    /// Do not read shell commands; run until interrupted (Ctrl+C) or --for ends.
    #[arg(long)]
    pub no_shell: bool,
    /// Stop after this many seconds (for scripts and benchmarks).
    #[arg(long = "for", value_name = "SECONDS")]
    pub run_for: Option<f64>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// List every component compiled into this binary.
    List,
    /// Print a component's conf lines: their arguments, types, units, ranges and
    /// defaults (or this help with no NAME).
    Help {
        /// A component (`jderobot list` shows them).
        name: Option<String>,
    },
    /// Parse and validate CONF: its grammar, then every component built from its
    /// lines as a run would, without running any schema; exit 1 on problems.
    Check {
        /// The conf file to check.
        conf: PathBuf,
    },
    /// Print what an MCAP recording holds: channels, counts, rates, duration, and
    /// what was lost if the file was cut short or is corrupt (with the offsets).
    #[cfg(feature = "_mcap")]
    Info {
        /// The .mcap file.
        file: PathBuf,
    },
}

/// What is logged when `RUST_LOG` is not set: our warnings; winit's errors only;
/// nothing of RustDDS's own log (it logs teardown order and peers' unusual but
/// harmless traffic as warnings and errors; what matters reaches us as results and
/// is said in our lines). `RUST_LOG=warn` shows everything.
const DEFAULT_LOG: &str = "warn,winit=error,rustdds=off";

/// Runs the program; returns its exit code.
pub fn main() -> ExitCode {
    // A python schema's worker is this binary started again.
    #[cfg(feature = "python")]
    if let Some(code) = crate::schemas::python::main_if_worker() {
        return code;
    }
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(DEFAULT_LOG)),
        )
        .with_writer(crate::output::LogWriter)
        .init();
    let cli = Cli::parse();
    match cli.command {
        Some(Command::List) => {
            list();
            ExitCode::SUCCESS
        }
        Some(Command::Check { conf }) => check(&conf),
        Some(Command::Help { name: None }) => {
            use clap::CommandFactory;
            let _ = Cli::command().print_long_help();
            print!("{}", shell_commands(None));
            ExitCode::SUCCESS
        }
        Some(Command::Help { name: Some(name) }) => help(&name),
        #[cfg(feature = "_mcap")]
        Some(Command::Info { file }) => info(&file),
        None => run(&cli),
    }
}

fn list() {
    let comps = registry::components();
    if comps.is_empty() {
        println!("no components compiled in; build with `--features full`");
    }
    for c in comps {
        println!("{:<8} {:<16} {}", c.kind.to_string(), c.name, c.summary);
    }
    let compiled: Vec<&str> = registry::components().iter().map(|c| c.feature).collect();
    let missing: Vec<&&str> = registry::ALL_COMPONENT_FEATURES
        .iter()
        .filter(|f| !compiled.contains(f))
        .collect();
    if !missing.is_empty() {
        let names: Vec<&str> = missing.iter().map(|s| **s).collect();
        println!(
            "\nnot compiled in (add with `--features NAME`): {}",
            names.join(", ")
        );
    }
}

/// The shell commands the components bring (of `component` only, if given),
/// from their registration: what the shell's `help` lists too.
fn shell_commands(component: Option<&str>) -> String {
    let cmds: Vec<_> = registry::commands()
        .into_iter()
        .filter(|c| component.is_none_or(|n| c.component == n))
        .collect();
    if cmds.is_empty() {
        return String::new();
    }
    let mut out = String::from("\nShell commands it brings:\n");
    if component.is_none() {
        out = String::from("\nShell commands the components bring:\n");
    }
    for c in cmds {
        let from = if component.is_none() {
            format!(" ({})", c.component)
        } else {
            String::new()
        };
        out.push_str(&format!(
            "  {:<28}{}.{from}\n",
            format!("{} {}", c.name, c.usage),
            c.help
        ));
    }
    out
}

/// `jderobot help NAME`: the component's lines from its declaration; a name that
/// is both a driver and a service (`ros2`) prints both.
fn help(name: &str) -> ExitCode {
    let entries: Vec<_> = registry::components()
        .into_iter()
        .filter(|c| c.name == name)
        .collect();
    if entries.is_empty() {
        if let Err(e) = registry::lookup(None, name) {
            eprintln!("{e}");
        }
        return ExitCode::FAILURE;
    }
    for (i, entry) in entries.iter().enumerate() {
        if i > 0 {
            println!();
        }
        match entry.lines {
            Some(lines) => print!(
                "{}",
                crate::conf::settings::help_text(
                    entry.kind,
                    entry.name,
                    entry.summary,
                    lines.decl,
                    ""
                )
            ),
            None => println!(
                "{} {}: {}

Its lines are not declared yet; its module documentation lists them.",
                entry.kind, entry.name, entry.summary
            ),
        }
    }
    print!("{}", shell_commands(Some(name)));
    ExitCode::SUCCESS
}

/// `jderobot info FILE.mcap`.
#[cfg(feature = "_mcap")]
fn info(file: &std::path::Path) -> ExitCode {
    match crate::mcapfmt::Summary::read(file) {
        Ok((s, _)) => {
            print!("{}", s.report(file));
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}

fn check(file: &std::path::Path) -> ExitCode {
    let conf = match Conf::load(file) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let mut problems = loader::check(&conf);
    if problems.is_empty()
        && let Err(e) = loader::check_loads(&conf)
    {
        problems.push(e);
    }
    if problems.is_empty() {
        println!(
            "{}: ok ({} sections, {} directives)",
            file.display(),
            conf.sections.len(),
            conf.directives.len()
        );
        ExitCode::SUCCESS
    } else {
        for p in problems {
            eprintln!("{p}");
        }
        ExitCode::FAILURE
    }
}

fn run(cli: &Cli) -> ExitCode {
    let conf = match Conf::load(&cli.conf) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            if !cli.conf.exists() {
                eprintln!(
                    "usage: jderobot [CONF] (default ./jde.conf); try `jderobot examples/myschema.conf`, or `jderobot --help`"
                );
            }
            return ExitCode::from(2);
        }
    };
    let problems = loader::check(&conf);
    if !problems.is_empty() {
        for p in problems {
            eprintln!("{p}");
        }
        return ExitCode::from(2);
    }
    eprintln!("Configuration from {}", cli.conf.display());
    let rt = match loader::start(&conf) {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let headless = cli.headless || !display_available();
    #[cfg(not(feature = "gui"))]
    if !headless {
        tracing::warn!("this binary has no GUI compiled in; running headless");
    }
    {
        // SIGINT, SIGTERM, SIGHUP, Ctrl+Z, an abort or a panic: every actuator's
        // stop first (crate::estop), then, for the ones that end the program, the
        // shutdown. Ctrl+C stops a shell command that is waiting (echo N), else
        // the program.
        let rt = rt.clone();
        let quit = move |code: i32| {
            rt.shutdown();
            std::process::exit(code);
        };
        if let Err(e) = crate::estop::install(shell::interrupt_foreground, quit) {
            tracing::error!(
                "cannot catch signals ({e}): Ctrl+C or SIGTERM will not stop the motors first"
            );
        }
    }
    if let Some(secs) = cli.run_for {
        let rt = rt.clone();
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_secs_f64(secs.max(0.0)));
            rt.shutdown();
            std::process::exit(0);
        });
    }
    // With a display, the shell runs on its own thread and the window (once a GUI
    // service is loaded) on this one.
    #[cfg(feature = "gui")]
    if !headless {
        return window::launch(rt, conf, cli.no_shell);
    }
    #[cfg(feature = "gui")]
    window::headless_notice(&rt, !cli.no_shell);
    if cli.no_shell {
        loop {
            std::thread::park();
        }
    }
    let _ = shell::run(rt.clone(), conf);
    rt.shutdown();
    ExitCode::SUCCESS
}

/// Whether a graphical display is reachable (X11 or Wayland).
pub fn display_available() -> bool {
    std::env::var_os("DISPLAY").is_some_and(|d| !d.is_empty())
        || std::env::var_os("WAYLAND_DISPLAY").is_some_and(|d| !d.is_empty())
}

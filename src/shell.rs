//! The jde shell: the seed's text shell, with two states.
//!
//! Main state (prompt `jdeC $> `): `help`/`?`, `cd DIR`, `dir [DIR]`, `pwd`,
//! `view FILE`, `ls`, `load_driver|load_service|load_schema|load NAME [conf]`, `ps`,
//! `run`, `stop`, `show`, `hide NAME`, `zoom NAME`, `echo NAME [N]`,
//! `set NAME FIELD=VALUE ...`, `show_license`, `quit`/`exit`. Typing a loaded
//! schema's name runs it, as in 4.3.
//!
//! Schema state (after `zoom NAME`, prompt `jdeC[NAME] $> `): `help`/`?`, `cd`,
//! `dir`, `pwd`, `view`, `run`, `stop`, `show`, `hide` (4.3's `resume`, `suspend`,
//! `guiresume`, `guisuspend` too), `init [conf]`, `terminate`, `exit` back to main.
//!
//! On a terminal the shell edits lines with rustyline: TAB completes commands,
//! component names and file names, and history persists in
//! `$XDG_DATA_HOME/jderobot/history` (or `~/.local/share/jderobot/history`).
//! With piped standard input it reads one command a line and ends at end of input,
//! so runs can be scripted. Ctrl+C stops a waiting `echo NAME N` (at the prompt it
//! clears the line). Nothing typed can kill the program: every mistake gets
//! a one-line explanation on standard error.

use std::{
    io::{BufRead, Write},
    path::{Path, PathBuf},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};

use crate::{
    conf::{Conf, Kind},
    interfaces::AnyInterface,
    loader, output, registry,
    runtime::Runtime,
};

/// What the shell should do after a command.
#[derive(Debug, PartialEq, Eq)]
pub enum Flow {
    Continue,
    Quit,
}

/// A command's name, usage and one-line help.
type CommandDoc = (&'static str, &'static str, &'static str);

/// A command of the shell's own tables, `NAME [USAGE]: help`, as a [`CommandDoc`].
fn doc(line: &'static str) -> CommandDoc {
    let (head, help) = line.split_once(": ").unwrap_or((line, ""));
    let (name, usage) = head.split_once(' ').unwrap_or((head, ""));
    (name, usage, help)
}

/// The commands of both states.
const SHARED_COMMANDS: &[&str] = &[
    "help [COMMAND]: Display this help text",
    "? [COMMAND]: Synonym for `help'",
    "cd DIR: Change working directory to DIR",
    "dir [DIR]: List files in the working directory (or DIR)",
    "pwd: Print the current working directory",
    "view FILE: View the contents of FILE",
];

/// The main state's own commands.
const MAIN_COMMANDS: &[&str] = &[
    "ls: List loaded schemas, drivers, services and interfaces",
    "load_driver NAME [CONF]: Load driver NAME",
    "load_service NAME [CONF]: Load service NAME",
    "load_schema NAME [CONF]: Load schema NAME",
    "load NAME [CONF]: Load component NAME, whatever its kind",
    "ps: Print schemas' states, ips and jitter, and interfaces' clocks and rates",
    "run NAME: Run schema NAME (or resume interface NAME)",
    "stop NAME: Stop schema NAME (or suspend interface NAME)",
    "show NAME: Show the GUI panel of schema NAME",
    "hide NAME: Hide the GUI panel of schema NAME",
    "zoom NAME: Change to schema state of NAME",
    "reload NAME: Build schema NAME again from its conf (a python schema reads its program again)",
    "echo NAME [N]: Print interface NAME's value, or its next N values",
    "set NAME FIELD=VALUE...: Write fields of actuator interface NAME",
    "show_license: Show the license",
    "exit: Quit using jderobot",
    "quit: Quit using jderobot",
];

/// The schema state's own commands.
const SCHEMA_COMMANDS: &[&str] = &[
    "run: Run the schema",
    "stop: Stop the schema",
    "show: Show the schema's GUI panel",
    "hide: Hide the schema's GUI panel",
    "init [CONF]: Init the schema again from CONF (default: the main conf file)",
    "terminate: Terminate the schema",
    "exit: Exit schema state",
];

/// Every command of the main state (`zoomed` false) or the schema state: the
/// shell's own and, in main state, those the compiled-in components register
/// ([`registry::ShellCommand`]).
fn commands(zoomed: bool) -> Vec<CommandDoc> {
    let own = if zoomed {
        SCHEMA_COMMANDS
    } else {
        MAIN_COMMANDS
    };
    let mut v: Vec<CommandDoc> = SHARED_COMMANDS
        .iter()
        .chain(own)
        .copied()
        .map(doc)
        .collect();
    if !zoomed {
        v.extend(
            registry::commands()
                .iter()
                .map(|c| (c.name, c.usage, c.help)),
        );
    }
    v
}

/// Aliases of schema-state commands (4.3's older names).
fn schema_alias(cmd: &str) -> &str {
    match cmd {
        "resume" => "run",
        "suspend" => "stop",
        "guiresume" => "show",
        "guisuspend" => "hide",
        c => c,
    }
}

const LICENSE: &str = "jderobot: the JDE 4.3 robotics suite rebuilt in Rust.
Copyright (C) 1997-2009 JDE Developers Team; this rebuild by the jderobot developers.

This program is free software: you can redistribute it and/or modify it under the
terms of the GNU General Public License as published by the Free Software
Foundation, either version 3 of the License, or (at your option) any later version.

This program is distributed in the hope that it will be useful, but WITHOUT ANY
WARRANTY; without even the implied warranty of MERCHANTABILITY or FITNESS FOR A
PARTICULAR PURPOSE. See the GNU General Public License for more details.";

/// The shell's state.
pub struct Shell {
    rt: Arc<Runtime>,
    conf: Conf,
    zoomed: Option<String>,
}

impl Shell {
    pub fn new(rt: Arc<Runtime>, conf: Conf) -> Self {
        Shell {
            rt,
            conf,
            zoomed: None,
        }
    }

    /// The prompt for the current state.
    pub fn prompt(&self) -> String {
        match &self.zoomed {
            Some(s) => format!("jdeC[{s}] $> "),
            None => "jdeC $> ".to_string(),
        }
    }

    /// The schema zoomed into, if any.
    pub fn zoomed(&self) -> Option<&str> {
        self.zoomed.as_deref()
    }

    /// Leaves schema state (Ctrl+D there); returns false if already in main state.
    pub fn unzoom(&mut self) -> bool {
        self.zoomed.take().is_some()
    }

    /// Runs one command line, writing its output to `out` and errors to `err`.
    pub fn execute(&mut self, line: &str, out: &mut dyn Write, err: &mut dyn Write) -> Flow {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&cmd, args)) = words.split_first() else {
            return Flow::Continue;
        };
        let result = match self.zoomed.clone() {
            Some(schema) => self.schema_command(&schema, schema_alias(cmd), args, out),
            None => self.main_command(cmd, args, out),
        };
        match result {
            Ok(flow) => flow,
            Err(msg) => {
                let _ = writeln!(err, "{msg}");
                Flow::Continue
            }
        }
    }

    /// A main-state command: the shell's own, a component's, or a schema's name.
    fn main_command(
        &mut self,
        cmd: &str,
        args: &[&str],
        out: &mut dyn Write,
    ) -> Result<Flow, String> {
        let rt = self.rt.clone();
        match cmd {
            "help" | "?" => help(false, args, out),
            "cd" | "dir" | "pwd" | "view" => files(cmd, args, out),
            "ls" => ls(&rt, out),
            "load_driver" | "load_service" | "load_schema" | "load" => self.load(cmd, args, out),
            "ps" => {
                ps(&rt, out);
                Ok(Flow::Continue)
            }
            "run" | "stop" | "show" | "hide" => switch(&rt, cmd, one(cmd, args, "NAME")?),
            "zoom" => self.zoom(one(cmd, args, "NAME")?),
            "echo" => echo_command(&rt, args, out),
            "set" => set(&rt, args, out),
            "reload" => {
                let name = one(cmd, args, "NAME")?;
                loader::reinit(&rt, name, None)
                    .map(|_| {
                        w(out, format!("{name} reloaded"));
                        Flow::Continue
                    })
                    .map_err(|e| format!("reload: {e}"))
            }
            "show_license" => {
                w(out, LICENSE.to_string());
                Ok(Flow::Continue)
            }
            "exit" | "quit" => Ok(Flow::Quit),
            other => self.other(other, args, out),
        }
    }

    /// A component's command ([`registry::ShellCommand`]), or a schema's name
    /// (which runs it, as in 4.3).
    fn other(&self, cmd: &str, args: &[&str], out: &mut dyn Write) -> Result<Flow, String> {
        if let Some(c) = registry::command(cmd) {
            return (c.run)(&self.rt, args, out).map(|_| Flow::Continue);
        }
        if self.rt.schema(cmd).is_some() && args.is_empty() {
            return switch(&self.rt, "run", cmd);
        }
        Err(format!(
            "{cmd}: No such command for jderobot. Type `help' for the list of commands."
        ))
    }

    /// `load_driver|load_service|load_schema|load NAME [CONF]`.
    fn load(&self, cmd: &str, args: &[&str], out: &mut dyn Write) -> Result<Flow, String> {
        let kind = match cmd {
            "load_driver" => Some(Kind::Driver),
            "load_service" => Some(Kind::Service),
            "load_schema" => Some(Kind::Schema),
            _ => None,
        };
        let (name, file) = match args {
            [n] => (*n, None),
            [n, f] => (*n, Some(PathBuf::from(f))),
            _ => {
                return Err(format!(
                    "{cmd} command accepts 1 or 2 args only: {cmd} NAME [CONF]"
                ));
            }
        };
        loader::load(&self.rt, &self.conf, kind, name, file.as_deref())
            .map_err(|e| format!("{cmd}: {e}"))?;
        w(out, format!("{name} loaded"));
        Ok(Flow::Continue)
    }

    /// `zoom NAME`: schema state.
    fn zoom(&mut self, name: &str) -> Result<Flow, String> {
        if self.rt.schema(name).is_none() {
            return Err(format!(
                "zoom: `{name}` is not a loaded schema; loaded: {}",
                self.rt.schema_names().join(", ")
            ));
        }
        self.zoomed = Some(name.to_string());
        Ok(Flow::Continue)
    }

    fn schema_command(
        &mut self,
        schema: &str,
        cmd: &str,
        args: &[&str],
        out: &mut dyn Write,
    ) -> Result<Flow, String> {
        let rt = self.rt.clone();
        let res = match cmd {
            "help" | "?" => return help(true, args, out),
            "cd" | "dir" | "pwd" | "view" => return files(cmd, args, out),
            "run" => rt.run(schema).map_err(|e| e.to_string()),
            "stop" => rt.stop(schema).map_err(|e| e.to_string()),
            "show" => rt.show(schema).map_err(|e| e.to_string()),
            "hide" => rt.hide(schema).map_err(|e| e.to_string()),
            "init" => {
                let file = args.first().map(Path::new);
                loader::reinit(&rt, schema, file)
                    .map(|_| w(out, format!("{schema} initialized")))
                    .map_err(|e| e.to_string())
            }
            "terminate" => rt
                .terminate_schema(schema)
                .map(|_| w(out, format!("{schema} terminated")))
                .map_err(|e| e.to_string()),
            "exit" | "quit" => {
                self.zoomed = None;
                w(out, String::new());
                return Ok(Flow::Continue);
            }
            other => {
                return Err(format!(
                    "{other}: No such command in schema state. Type `help' for the list, `exit' to leave."
                ));
            }
        };
        res.map(|_| Flow::Continue)
            .map_err(|e| format!("{cmd}: {e}"))
    }

    /// Every word TAB may complete after `before` (the words typed so far).
    pub fn candidates(&self, before: &[&str]) -> Vec<String> {
        candidates(&self.rt, self.zoomed.is_some(), before)
    }
}

/// Completion candidates after the words `before`, in main or schema state.
fn candidates(rt: &Runtime, zoomed: bool, before: &[&str]) -> Vec<String> {
    {
        if before.is_empty() {
            let mut v: Vec<String> = commands(zoomed).iter().map(|c| c.0.to_string()).collect();
            if !zoomed {
                v.extend(rt.schema_names());
            }
            return v;
        }
        if before.len() > 1 {
            return Vec::new();
        }
        match (zoomed, schema_alias(before[0])) {
            (false, "run" | "stop") => {
                let mut v = rt.schema_names();
                v.extend(rt.interfaces.names());
                v
            }
            (false, "show" | "hide" | "zoom") => rt.schema_names(),
            (false, "echo" | "set") => rt.interfaces.names(),
            (false, c @ ("load_driver" | "load_service" | "load_schema" | "load")) => {
                registry::components()
                    .into_iter()
                    .filter(|comp| match c {
                        "load_driver" => comp.kind == Kind::Driver,
                        "load_service" => comp.kind == Kind::Service,
                        "load_schema" => comp.kind == Kind::Schema,
                        _ => true,
                    })
                    .map(|comp| comp.name.to_string())
                    .collect()
            }
            _ => Vec::new(),
        }
    }
}

fn w(out: &mut dyn Write, line: String) {
    let _ = writeln!(out, "{line}");
}

fn help(zoomed: bool, args: &[&str], out: &mut dyn Write) -> Result<Flow, String> {
    let all = commands(zoomed);
    let matching: Vec<&CommandDoc> = all
        .iter()
        .filter(|c| args.is_empty() || args.contains(&c.0))
        .collect();
    if matching.is_empty() {
        let names: Vec<&str> = all.iter().map(|c| c.0).collect();
        return Err(format!(
            "No commands match `{}'.  Possibilities are: {}",
            args.join(" "),
            names.join(" ")
        ));
    }
    for &&(name, usage, doc) in &matching {
        w(out, format!("{:<28}{doc}.", format!("{name} {usage}")));
    }
    Ok(Flow::Continue)
}

fn files(cmd: &str, args: &[&str], out: &mut dyn Write) -> Result<Flow, String> {
    match (cmd, args) {
        ("pwd", []) => {
            let d = std::env::current_dir().map_err(|e| format!("pwd: {e}"))?;
            w(out, format!("Current directory is {}", d.display()));
        }
        ("cd", [dir]) => {
            std::env::set_current_dir(dir).map_err(|e| format!("cd: {dir}: {e}"))?;
        }
        ("cd", []) => {
            let home = std::env::var("HOME").map_err(|_| "cd: HOME is not set".to_string())?;
            std::env::set_current_dir(&home).map_err(|e| format!("cd: {home}: {e}"))?;
        }
        ("dir", [] | [_]) => {
            let dir = args.first().copied().unwrap_or(".");
            let mut entries: Vec<String> = std::fs::read_dir(dir)
                .map_err(|e| format!("dir: {dir}: {e}"))?
                .filter_map(|e| e.ok())
                .map(|e| {
                    let name = e.file_name().to_string_lossy().into_owned();
                    match e.metadata() {
                        Ok(m) if m.is_dir() => format!("{name}/"),
                        Ok(m) => format!("{name}  ({} bytes)", m.len()),
                        Err(_) => name,
                    }
                })
                .collect();
            entries.sort();
            for e in entries {
                w(out, e);
            }
        }
        ("view", [file]) => {
            let text = crate::files::FileError::read(std::path::Path::new(file))
                .map_err(|e| format!("view: {e}"))?;
            let _ = out.write_all(text.as_bytes());
            if !text.ends_with('\n') {
                w(out, String::new());
            }
        }
        (c, []) => return Err(format!("{c}: Argument required.")),
        (c, _) => return Err(format!("{c}: too many arguments.")),
    }
    Ok(Flow::Continue)
}

/// The one argument of `cmd`.
fn one<'a>(cmd: &str, args: &[&'a str], usage: &str) -> Result<&'a str, String> {
    match args {
        [a] => Ok(*a),
        [] => Err(format!("{cmd}: Argument required. Usage: {cmd} {usage}")),
        _ => Err(format!("{cmd}: takes one argument. Usage: {cmd} {usage}")),
    }
}

/// `ls`: schemas, drivers and services, interfaces.
fn ls(rt: &Runtime, out: &mut dyn Write) -> Result<Flow, String> {
    for s in rt.schema_names() {
        w(out, s);
    }
    for (d, k) in rt.drivers() {
        w(out, format!("{d} ({k})"));
    }
    for i in rt.interfaces.all() {
        w(
            out,
            format!("{} ({} interface of {})", i.name(), i.kind(), i.provider()),
        );
    }
    Ok(Flow::Continue)
}

/// `run|stop|show|hide NAME`.
fn switch(rt: &Runtime, cmd: &str, name: &str) -> Result<Flow, String> {
    match cmd {
        "run" => rt.run(name),
        "stop" => rt.stop(name),
        "show" => rt.show(name),
        _ => rt.hide(name),
    }
    .map(|_| Flow::Continue)
    .map_err(|e| format!("{cmd}: {e}"))
}

/// `echo NAME [N]`.
fn echo_command(rt: &Runtime, args: &[&str], out: &mut dyn Write) -> Result<Flow, String> {
    let (name, n) = match args {
        [n] => (*n, None),
        [n, c] => (
            *n,
            Some(
                c.parse::<u64>()
                    .map_err(|_| format!("echo: count `{c}` is not a whole number"))?,
            ),
        ),
        _ => return Err("echo: Usage: echo NAME [N]".into()),
    };
    let iface = rt
        .interfaces
        .get_any(name)
        .map_err(|e| format!("echo: {e}"))?;
    echo(&*iface, n, out)
}

/// `set NAME FIELD=VALUE ...`: writes an actuator's fields.
fn set(rt: &Runtime, args: &[&str], out: &mut dyn Write) -> Result<Flow, String> {
    let [name, fields @ ..] = args else {
        return Err("set: Usage: set NAME FIELD=VALUE ...".into());
    };
    if fields.is_empty() {
        return Err(format!("set: no FIELD=VALUE given for `{name}`"));
    }
    let iface = rt
        .interfaces
        .get_any(name)
        .map_err(|e| format!("set: {e}"))?;
    if !iface.is_actuator() {
        return Err(format!(
            "set: `{name}` is a {} sensor interface; only actuators (motors, \
             pantiltmotors, zoommotors) can be set",
            iface.kind()
        ));
    }
    let pairs: Vec<(&str, &str)> = fields
        .iter()
        .map(|f| {
            f.split_once('=')
                .ok_or_else(|| format!("set: `{f}` is not FIELD=VALUE"))
        })
        .collect::<Result<_, _>>()?;
    iface.set_fields(&pairs).map_err(|e| format!("set: {e}"))?;
    w(
        out,
        format!(
            "{} clock={} {}",
            iface.name(),
            iface.clock(),
            iface.describe()
        ),
    );
    Ok(Flow::Continue)
}

/// Prints `ps`: every schema (4.3's line plus jitter) and every interface.
pub fn ps(rt: &Runtime, out: &mut dyn Write) {
    for s in rt.status() {
        w(out, s.ps_line());
    }
    for i in rt.interfaces.all() {
        let mut line = format!(
            "{}: {:.0} ips, {} user(s), clock {} ({} interface of {})",
            i.name(),
            i.rate(),
            i.users(),
            i.clock(),
            i.kind(),
            i.provider()
        );
        if let Some(why) = i.stale() {
            line.push_str(&format!(
                ", STALE for {:.1} s: {why}",
                i.age().as_secs_f64()
            ));
        }
        w(out, line);
    }
    for p in registry::ps_lines() {
        if let Some(line) = (p.line)(rt) {
            w(out, format!("{}: {line}", p.component));
        }
    }
}

fn echo_line(i: &dyn AnyInterface) -> String {
    let stale = i
        .stale()
        .map(|why| format!(" STALE ({why})"))
        .unwrap_or_default();
    format!(
        "{} clock={} age={:.3}s{stale} {}",
        i.name(),
        i.clock(),
        i.age().as_secs_f64(),
        i.describe()
    )
}

/// Set while a command that waits (`echo NAME N`) runs, so that Ctrl+C stops that
/// command instead of the program.
static FOREGROUND: AtomicBool = AtomicBool::new(false);
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Called on Ctrl+C: interrupts the command that is waiting, if one is, and says so
/// (true); false when nothing is, and Ctrl+C should end the program.
pub fn interrupt_foreground() -> bool {
    let waiting = FOREGROUND.load(Ordering::Acquire);
    if waiting {
        INTERRUPTED.store(true, Ordering::Release);
    }
    waiting
}

/// Marks a waiting command for [`interrupt_foreground`] while it lives.
struct Foreground;

impl Foreground {
    fn start() -> Foreground {
        INTERRUPTED.store(false, Ordering::Release);
        FOREGROUND.store(true, Ordering::Release);
        Foreground
    }
    fn interrupted(&self) -> bool {
        INTERRUPTED.load(Ordering::Acquire)
    }
}

impl Drop for Foreground {
    fn drop(&mut self) {
        FOREGROUND.store(false, Ordering::Release);
    }
}

/// Prints an interface's value once, or its next `n` new values (Ctrl+C stops).
fn echo(i: &dyn AnyInterface, n: Option<u64>, out: &mut dyn Write) -> Result<Flow, String> {
    let Some(n) = n else {
        w(out, echo_line(i));
        return Ok(Flow::Continue);
    };
    let fg = Foreground::start();
    let mut last = i.clock();
    let patience = Duration::from_secs(5);
    for _ in 0..n {
        let t0 = Instant::now();
        loop {
            if fg.interrupted() {
                return Err("echo: interrupted".into());
            }
            if i.clock() != last {
                break;
            }
            if t0.elapsed() > patience {
                return Err(format!(
                    "echo: no new value of `{}` in {} s (is it running? `run {}`)",
                    i.name(),
                    patience.as_secs(),
                    i.name()
                ));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        last = i.clock();
        w(out, echo_line(i));
    }
    Ok(Flow::Continue)
}

/// Where history is kept.
pub fn history_file() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_DATA_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/share")))?;
    Some(base.join("jderobot").join("history"))
}

/// How a shell ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShellEnd {
    /// The user asked: `quit`, `exit`, or Ctrl+D at the terminal in main state.
    Quit,
    /// Piped standard input ended (a script's end, `</dev/null`, a desktop
    /// launcher): nobody asked the run to stop.
    EndOfInput,
}

/// Runs the shell until `quit`, Ctrl+D in main state, or end of piped input.
pub fn run(rt: Arc<Runtime>, conf: Conf) -> ShellEnd {
    let mut shell = Shell::new(rt, conf);
    if std::io::IsTerminal::is_terminal(&std::io::stdin()) {
        match interactive(&mut shell) {
            Ok(()) => return ShellEnd::Quit,
            Err(e) => eprintln!("line editor unavailable ({e}); reading plain lines"),
        }
    }
    let stdin = std::io::stdin();
    let mut bytes = Vec::new();
    for n in 1.. {
        bytes.clear();
        match stdin.lock().read_until(b'\n', &mut bytes) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) => {
                eprintln!("shell: standard input: {e}");
                break;
            }
        }
        let mut out = std::io::stdout();
        let mut err = std::io::stderr();
        // A line that is not text is refused on its own; the lines after it still run.
        let Ok(line) = std::str::from_utf8(&bytes) else {
            w(
                &mut err,
                format!("line {n} of standard input is not UTF-8 text; ignored"),
            );
            continue;
        };
        if shell.execute(line.trim(), &mut out, &mut err) == Flow::Quit {
            return ShellEnd::Quit;
        }
    }
    ShellEnd::EndOfInput
}

mod editor {
    //! rustyline glue: completion of commands, names ([`super::candidates`]) and files.
    use crate::runtime::Runtime;
    use rustyline::{
        Context, Helper,
        completion::{Completer, FilenameCompleter, Pair},
        highlight::Highlighter,
        hint::Hinter,
        validate::Validator,
    };
    use std::sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    };

    pub struct JdeHelper {
        pub rt: Arc<Runtime>,
        pub zoomed: Arc<AtomicBool>,
        pub files: FilenameCompleter,
    }

    impl Completer for JdeHelper {
        type Candidate = Pair;
        fn complete(
            &self,
            line: &str,
            pos: usize,
            ctx: &Context<'_>,
        ) -> rustyline::Result<(usize, Vec<Pair>)> {
            let head = &line[..pos];
            let start = head.rfind(char::is_whitespace).map(|i| i + 1).unwrap_or(0);
            let before: Vec<&str> = head[..start].split_whitespace().collect();
            let word = &head[start..];
            let file_cmds = ["cd", "dir", "view", "init"];
            let is_file_arg = !before.is_empty()
                && (file_cmds.contains(&before[0])
                    || (before.len() == 2 && before[0].starts_with("load")));
            if is_file_arg {
                return self.files.complete(line, pos, ctx);
            }
            let zoomed = self.zoomed.load(Ordering::Relaxed);
            let mut pairs: Vec<Pair> = super::candidates(&self.rt, zoomed, &before)
                .into_iter()
                .filter(|c| c.starts_with(word))
                .map(|c| Pair {
                    display: c.clone(),
                    replacement: format!("{c} "),
                })
                .collect();
            pairs.sort_by(|a, b| a.display.cmp(&b.display));
            pairs.dedup_by(|a, b| a.display == b.display);
            Ok((start, pairs))
        }
    }
    impl Hinter for JdeHelper {
        type Hint = String;
    }
    impl Highlighter for JdeHelper {}
    impl Validator for JdeHelper {}
    impl Helper for JdeHelper {}
}

fn interactive(shell: &mut Shell) -> rustyline::Result<()> {
    use rustyline::{Config, Editor, ExternalPrinter, error::ReadlineError, history::FileHistory};
    let config = Config::builder()
        .completion_type(rustyline::CompletionType::List)
        .auto_add_history(true)
        .build();
    let mut rl: Editor<editor::JdeHelper, FileHistory> = Editor::with_config(config)?;
    let zoomed = Arc::new(std::sync::atomic::AtomicBool::new(false));
    rl.set_helper(Some(editor::JdeHelper {
        rt: shell.rt.clone(),
        zoomed: zoomed.clone(),
        files: rustyline::completion::FilenameCompleter::new(),
    }));
    let history = history_file();
    if let Some(h) = &history {
        let _ = rl.load_history(h);
    }
    if let Ok(mut printer) = rl.create_external_printer() {
        output::set_sink(Some(Box::new(move |line: String| {
            let _ = printer.print(format!("{line}\n"));
        })));
    }
    loop {
        zoomed.store(shell.zoomed.is_some(), std::sync::atomic::Ordering::Relaxed);
        match rl.readline(&shell.prompt()) {
            Ok(line) => {
                let mut out = std::io::stdout();
                let mut err = std::io::stderr();
                if shell.execute(line.trim(), &mut out, &mut err) == Flow::Quit {
                    break;
                }
            }
            Err(ReadlineError::Eof) => {
                if !shell.unzoom() {
                    break;
                }
                println!();
            }
            Err(ReadlineError::Interrupted) => continue,
            Err(e) => {
                output::set_sink(None);
                return Err(e);
            }
        }
    }
    output::set_sink(None);
    if let Some(h) = &history {
        if let Some(dir) = h.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        let _ = rl.save_history(h);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_table_line_reads_as_name_usage_help() {
        assert_eq!(doc("pwd: Print it"), ("pwd", "", "Print it"));
        assert_eq!(
            doc("set NAME FIELD=VALUE...: Write: fields"),
            ("set", "NAME FIELD=VALUE...", "Write: fields")
        );
        for line in [SHARED_COMMANDS, MAIN_COMMANDS, SCHEMA_COMMANDS].concat() {
            let (name, usage, help) = doc(line);
            assert!(!name.is_empty() && !help.is_empty(), "{line}");
            assert!(!name.contains(':') && !usage.contains(": "), "{line}");
        }
    }
}

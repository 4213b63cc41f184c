//! The interactive shell through a real pty: prompts, TAB completion, history
//! across runs, zoom and exit, Ctrl+D, and schema output that does not garble the
//! line being typed.

use std::process::Command;

use rexpect::session::{PtySession, spawn_command};

const BIN: &str = env!("CARGO_BIN_EXE_jderobot");

fn spawn(conf: &str, data_home: &std::path::Path) -> PtySession {
    let mut cmd = Command::new(BIN);
    cmd.args(["--headless", conf])
        .env("XDG_DATA_HOME", data_home)
        .env("TERM", "xterm")
        .env("RUST_LOG", "off")
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY");
    spawn_command(cmd, Some(20_000)).expect("spawn in a pty")
}

/// Writes `text` as `dir/jde.conf`; returns its path.
fn write_conf(dir: &std::path::Path, text: &str) -> String {
    let conf = dir.join("jde.conf");
    std::fs::write(&conf, text).unwrap();
    conf.to_str().unwrap().to_string()
}

fn quiet_conf(dir: &std::path::Path) -> String {
    write_conf(
        dir,
        "load_schema myschema\nload_schema ping\nload_schema pong\n",
    )
}

#[test]
fn tab_completion_zoom_exit_and_ctrl_d() {
    let dir = tempfile::tempdir().unwrap();
    let conf = quiet_conf(dir.path());
    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    // Command completion: "zo" + TAB -> "zoom ", then a schema name: "mys" + TAB.
    p.send("zo\t").unwrap();
    p.flush().unwrap();
    p.exp_string("zoom").unwrap();
    p.send("mys\t").unwrap();
    p.flush().unwrap();
    p.exp_string("myschema").unwrap();
    p.send("\r").unwrap();
    p.flush().unwrap();
    p.exp_string("jdeC[myschema] $> ").unwrap();
    // Schema state: help lists init/terminate.
    p.send_line("help").unwrap();
    p.exp_string("terminate").unwrap();
    p.exp_string("jdeC[myschema] $> ").unwrap();
    // `exit` goes back to main state.
    p.send_line("exit").unwrap();
    p.exp_string("jdeC $> ").unwrap();
    // Ctrl+D in schema state goes back to main, in main state it quits.
    p.send_line("zoom ping").unwrap();
    p.exp_string("jdeC[ping] $> ").unwrap();
    p.send_control('d').unwrap();
    p.exp_string("jdeC $> ").unwrap();
    // Several candidates: "p" + TAB rings, a second TAB lists ping, pong, ps, pwd.
    p.send("p\t\t").unwrap();
    p.flush().unwrap();
    p.exp_string("pong").unwrap();
    p.send_control('u').unwrap();
    p.send_control('d').unwrap();
    p.exp_eof().unwrap();
}

#[test]
fn file_name_completion() {
    let dir = tempfile::tempdir().unwrap();
    let conf = quiet_conf(dir.path());
    std::fs::write(
        dir.path().join("uniquely_named_file.txt"),
        "hello from the file\n",
    )
    .unwrap();
    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    p.send_line(&format!("cd {}", dir.path().display()))
        .unwrap();
    p.exp_string("jdeC $> ").unwrap();
    p.send("view uniq\t").unwrap();
    p.flush().unwrap();
    p.exp_string("uniquely_named_file.txt").unwrap();
    p.send("\r").unwrap();
    p.flush().unwrap();
    p.exp_string("hello from the file").unwrap();
    p.send_line("quit").unwrap();
    p.exp_eof().unwrap();
}

#[test]
fn history_persists_across_runs() {
    let dir = tempfile::tempdir().unwrap();
    let conf = quiet_conf(dir.path());
    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    p.send_line("show_license").unwrap();
    p.exp_string("General Public License").unwrap();
    p.exp_string("jdeC $> ").unwrap();
    p.send_line("quit").unwrap();
    p.exp_eof().unwrap();
    let history = std::fs::read_to_string(dir.path().join("jderobot/history")).unwrap();
    assert!(history.contains("show_license"), "{history}");

    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    // Up arrow recalls the previous run's last command ("quit" then "show_license").
    p.send("\x1b[A\x1b[A\r").unwrap();
    p.flush().unwrap();
    p.exp_string("General Public License").unwrap();
    p.send_line("quit").unwrap();
    p.exp_eof().unwrap();
}

#[test]
fn schema_output_does_not_garble_the_line_being_typed() {
    let dir = tempfile::tempdir().unwrap();
    let conf = write_conf(
        dir.path(),
        "schema myschema\ncycle 50\nend_schema\nload_schema myschema\nrun myschema\n",
    );
    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    p.send("sho").unwrap();
    p.flush().unwrap();
    // Hello lines keep coming; after one, the prompt and the typed text are redrawn.
    p.exp_string("-->Hello world!").unwrap();
    p.exp_string("jdeC $> sho").unwrap();
    p.send("w_license\r").unwrap();
    p.flush().unwrap();
    p.exp_string("General Public License").unwrap();
    p.send_line("quit").unwrap();
    p.exp_eof().unwrap();
}

/// Ctrl+Z at the prompt: rustyline sends the process SIGTSTP, whose handler
/// (src/estop.rs) runs every actuator's stop and suspends the process. Here the
/// child leads a session of its own (an orphaned process group), where the
/// kernel ignores a stop signal's default action, so it runs on: the shell must
/// answer after it as before (the handler waits for the suspension, not forever).
#[test]
fn ctrl_z_at_the_prompt_leaves_the_shell_working() {
    let dir = tempfile::tempdir().unwrap();
    let conf = write_conf(
        dir.path(),
        "driver simulator\nprovides encoders\nend_driver\nload_driver simulator\n",
    );
    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    p.send_control('z').unwrap();
    p.send_line("echo encoders").unwrap();
    p.exp_string("encoders clock=").unwrap();
    p.send_line("quit").unwrap();
    p.exp_eof().unwrap();
}

#[test]
fn ctrl_c_stops_a_waiting_echo_not_the_program() {
    let dir = tempfile::tempdir().unwrap();
    let conf = write_conf(
        dir.path(),
        "driver simulator\nprovides encoders\nend_driver\nload_driver simulator\n",
    );
    let mut p = spawn(&conf, dir.path());
    p.exp_string("jdeC $> ").unwrap();
    p.send_line("echo encoders 100000").unwrap();
    p.exp_string("encoders clock=").unwrap();
    p.send_control('c').unwrap();
    p.exp_string("echo: interrupted").unwrap();
    p.exp_string("jdeC $> ").unwrap();
    // The program is alive: it answers, and a Ctrl+C at the prompt does not end it.
    p.send_control('c').unwrap();
    p.exp_string("jdeC $> ").unwrap();
    p.send_line("echo encoders").unwrap();
    p.exp_string("encoders clock=").unwrap();
    p.send_line("quit").unwrap();
    p.exp_eof().unwrap();
}

//! Runs a conf with the GUI window: the shell on its own thread, the window on the
//! main thread once a GUI service is loaded.

use std::{
    process::ExitCode,
    sync::{Arc, mpsc},
    time::Duration,
};

use crate::{
    conf::Conf,
    gui::{GuiHost, gui_loaded, run_window},
    runtime::Runtime,
    shell::{self, ShellEnd},
};

/// Says why no window opens when a GUI service is loaded but the run is headless,
/// and, with a shell, how to watch the run from it.
pub fn headless_notice(rt: &Runtime, shell: bool) {
    if gui_loaded(rt) {
        eprintln!("gui: no display or --headless: running without the window");
        if shell {
            eprintln!("gui: watch from the shell instead: `ps`, `echo encoders 5`, `help`");
        }
    }
}

/// Runs the shell on its own thread and, once a GUI service is loaded (now or later
/// from the shell), the window on this thread. Returns when the user quits (the
/// shell's `quit`, the window's Quit or close, SIGINT/SIGTERM); the runtime is shut
/// down either way. The end of piped standard input ends only the shell while the
/// window is open: a run started from a desktop launcher, with `</dev/null` or
/// under `nohup` keeps its window.
pub fn launch(rt: Arc<Runtime>, conf: Conf, no_shell: bool) -> ExitCode {
    // Panel positions are kept beside the shell's history.
    let layout = shell::history_file().map(|h| h.with_file_name("panels"));
    let host = GuiHost::new(rt.clone()).with_layout_file(layout);
    let handle = host.close_handle();
    let term = terminal::Saved::now();
    let (tx, rx) = mpsc::channel::<()>();
    let mut _keep = None;
    if no_shell {
        _keep = Some(tx);
    } else {
        let (rt2, h) = (rt.clone(), handle.clone());
        let spawned = std::thread::Builder::new()
            .name("shell".into())
            .spawn(move || {
                if shell::run(rt2.clone(), conf) == ShellEnd::EndOfInput && gui_loaded(&rt2) {
                    eprintln!(
                        "shell: end of standard input; the window stays open until it is \
                         closed (or the process gets SIGINT/SIGTERM)"
                    );
                    return;
                }
                h.close();
                let _ = tx.send(());
            });
        if let Err(e) = spawned {
            eprintln!("cannot start the shell thread: {e}");
            rt.shutdown();
            return ExitCode::FAILURE;
        }
    }
    if !gui_loaded(&rt) && rt.status().iter().any(|s| s.shown) {
        eprintln!(
            "gui: panels are shown but no GUI service is loaded; `load_service gui` \
             (in the conf or the shell) opens the window"
        );
    }
    // Wait for a GUI service, or for the shell to end.
    loop {
        // Disconnected (no message) means the shell's input ended while the window
        // is wanted: keep waiting for it.
        if rx.recv_timeout(Duration::from_millis(50)).is_ok() {
            rt.shutdown();
            return ExitCode::SUCCESS;
        }
        if gui_loaded(&rt) {
            break;
        }
    }
    match run_window(host) {
        Ok(()) => {}
        Err(e) => {
            eprintln!("gui: cannot open the window ({e}); running without it");
            // Wait for the shell (or, with no shell or after its input ended, until
            // Ctrl+C or SIGTERM ends the run).
            if rx.recv().is_err() {
                loop {
                    std::thread::park();
                }
            }
        }
    }
    term.restore();
    rt.shutdown();
    ExitCode::SUCCESS
}

mod terminal {
    //! Restores the terminal's settings when the window ends the program while
    //! the line editor (on the shell's thread) has it in raw mode.

    pub struct Saved(Option<libc::termios>);

    impl Saved {
        pub fn now() -> Self {
            // SAFETY: tcgetattr only writes into the zeroed struct we own.
            unsafe {
                if libc::isatty(0) != 1 {
                    return Saved(None);
                }
                let mut t: libc::termios = std::mem::zeroed();
                if libc::tcgetattr(0, &mut t) == 0 {
                    Saved(Some(t))
                } else {
                    Saved(None)
                }
            }
        }

        pub fn restore(&self) {
            if let Some(t) = &self.0 {
                // SAFETY: restores settings read by tcgetattr on the same fd.
                unsafe {
                    libc::tcsetattr(0, libc::TCSANOW, t);
                }
            }
        }
    }
}

//! What both programs do around a command: the panic hook, logging on
//! stderr, the thread pool, removing unfinished outputs on a signal, and
//! turning the result into a message and an exit code.

use std::process::ExitCode;

/// On SIGINT or SIGTERM: removes the temporary file of every output still
/// being written and exits (130 or 143), so an interrupted render leaves
/// neither a partial picture nor a hidden temporary file. The signals are
/// registered before this returns.
pub fn exit_cleanly_on_signals() {
    use tokio::signal::unix::{SignalKind, signal};
    let Ok(rt) = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .build()
    else {
        return;
    };
    let registered = {
        let _in = rt.enter();
        signal(SignalKind::terminate()).and_then(|t| Ok((t, signal(SignalKind::interrupt())?)))
    };
    let Ok((mut term, mut int)) = registered else {
        return;
    };
    std::thread::spawn(move || {
        let (name, code) = rt.block_on(async {
            tokio::select! {
                _ = term.recv() => ("SIGTERM", 143),
                _ = int.recv() => ("SIGINT", 130),
            }
        });
        crate::output::remove_temporaries();
        eprintln!("error: stopped by {name}; outputs not finished were removed");
        std::process::exit(code);
    });
}

/// Reports a bug on one line, never as a trace; sets `-q`/`-v` logging on
/// stderr.
pub fn start(log: crate::cmd::Log) {
    let crate::cmd::Log { quiet, verbose } = log;
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!("error: internal error{at}: {message} (a bug in wisplight; please report it)");
    }));
    crate::cmd::set_quiet(quiet);
    let level = match (quiet, verbose) {
        (true, _) => tracing::Level::ERROR,
        (_, 0) => tracing::Level::WARN,
        (_, 1) => tracing::Level::INFO,
        _ => tracing::Level::DEBUG,
    };
    tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .init();
}

/// Sizes rayon's global pool (`--threads`), when given.
pub fn init_threads(threads: Option<u16>) -> anyhow::Result<()> {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.into())
            .build_global()?;
    }
    Ok(())
}

/// The exit code of a command's result, its error printed on one line:
/// 2 for a mistake in the command line (as clap's own errors), 1 for
/// anything that failed while running.
pub fn finish(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the context chain, outermost first.
            eprintln!("error: {e:#}");
            if e.chain().any(|c| c.is::<crate::cmd::Usage>()) {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

//! A stop asked for by a signal: SIGINT (Ctrl-C) or SIGTERM (a scheduler's time limit, `kill`).
//! Long work checks [`requested`] at its boundaries (a part of waveforms), finishes what it has
//! in flight, records it and ends, so the run folder stays whole and `--resume` goes on from
//! there. A second signal ends the process at once, as a user pressing Ctrl-C twice expects.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

struct Flags {
    signal: Arc<AtomicUsize>,
    seen: Arc<AtomicBool>,
}

static FLAGS: OnceLock<Flags> = OnceLock::new();

fn flags() -> &'static Flags {
    FLAGS.get_or_init(|| Flags {
        signal: Arc::new(AtomicUsize::new(0)),
        seen: Arc::new(AtomicBool::new(false)),
    })
}

/// Starts listening for SIGINT and SIGTERM, and turns SIGXFSZ into a failed write (on Unix;
/// elsewhere nothing is installed). Safe to call more than once.
pub fn install() {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let flags = flags();
        static INSTALLED: OnceLock<()> = OnceLock::new();
        INSTALLED.get_or_init(|| {
            // a file-size limit (RLIMIT_FSIZE, `ulimit -f`) would otherwise kill the process
            // with SIGXFSZ and no word; with a handler the write fails with EFBIG instead, and
            // the write's error names the file and says to free space and resume
            let _ = signal_hook::flag::register(
                signal_hook::consts::SIGXFSZ,
                Arc::new(AtomicBool::new(false)),
            );
            for sig in [SIGINT, SIGTERM] {
                // the second signal ends the process at once, with the exit code of every
                // failed run (1); registered first, so it sees the flag as the first signal
                // left it
                let _ = signal_hook::flag::register_conditional_shutdown(
                    sig,
                    1,
                    Arc::clone(&flags.seen),
                );
                let _ = signal_hook::flag::register(sig, Arc::clone(&flags.seen));
                let _ =
                    signal_hook::flag::register_usize(sig, Arc::clone(&flags.signal), sig as usize);
            }
        });
    }
}

/// Asks the work to stop at its next boundary, as `signal` would: for a host that watches
/// signals itself (the Python package polls the interpreter's, and installs no handler).
pub fn request(signal: i32) {
    flags()
        .signal
        .store(signal.max(1) as usize, Ordering::Relaxed);
}

/// Forgets a stop asked for earlier, before new work starts in a process that outlives it
/// (a Python session runs one campaign after another; the CLI runs one and exits).
pub fn clear() {
    let f = flags();
    f.signal.store(0, Ordering::Relaxed);
    f.seen.store(false, Ordering::Relaxed);
}

/// The signal that asked for a stop, if one did.
pub fn requested() -> Option<i32> {
    let s = FLAGS.get()?.signal.load(Ordering::Relaxed);
    (s != 0).then_some(s as i32)
}

/// Work whose result is of no use once a stop is asked for (a single pulse simulated in
/// memory for a host that raises the interruption) drops what is left of it at its next
/// chunk of rays: a host asks for that with [`abandon`]. A run's parts never do: a run
/// finishes the part in hand so that it can be kept.
static ABANDON: AtomicBool = AtomicBool::new(false);

/// Asks in-memory work to stop at its next chunk of rays (see [`ABANDON`]).
pub fn abandon() {
    ABANDON.store(true, Ordering::Relaxed);
}

/// Whether in-memory work should stop (see [`abandon`]).
#[inline]
pub fn abandoning() -> bool {
    ABANDON.load(Ordering::Relaxed)
}

/// Forgets an [`abandon`] before new work starts.
pub fn clear_abandon() {
    ABANDON.store(false, Ordering::Relaxed);
}

/// The signal's name, for messages.
pub fn name(signal: i32) -> String {
    match signal {
        2 => "SIGINT".to_string(),
        15 => "SIGTERM".to_string(),
        s => format!("signal {s}"),
    }
}

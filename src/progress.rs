//! What a long stage shows while it works: a progress bar on a terminal, plain log lines
//! otherwise (a batch job's log file).

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::{Arc, RwLock};

/// Where log lines go instead of stderr: a host's own logging (the Python package hands
/// them to its `lidarsim` logger).
pub type Sink = Arc<dyn Fn(&str) + Send + Sync>;

static SINK: RwLock<Option<Sink>> = RwLock::new(None);

/// Sends every later log line to `sink` (None: back to stderr). Progress bars are then not
/// drawn: their news comes as log lines, as in a batch job's log.
pub fn set_sink(sink: Option<Sink>) {
    *SINK.write().unwrap_or_else(|e| e.into_inner()) = sink;
}

fn sink() -> Option<Sink> {
    SINK.read().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Whether progress is shown as a bar redrawn on a terminal, rather than as log lines.
pub fn interactive() -> bool {
    std::io::stderr().is_terminal() && sink().is_none()
}

/// A progress bar on a terminal; hidden otherwise (stages then log plain lines).
pub fn progress(len: u64, what: &str) -> ProgressBar {
    if !interactive() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} pulses {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

pub fn log(line: &str) {
    match sink() {
        Some(f) => f(line),
        None => tell(&format!("lidarsim: {line}")),
    }
}

/// A line on standard error, or nothing where that is closed (`2>&1 | head -1`): the run goes
/// on and writes its files, which are what it is for.
pub fn tell(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

/// `text` on standard output. A closed or full output (`| head -1`, `> /dev/full`) is an
/// error the command ends on (exit code 1), not a panic.
pub fn say(text: &str) -> crate::error::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| crate::error::Error::msg(format!("cannot write to standard output: {e}")))
}

/// Gives the memory the allocator holds free back to the system. glibc keeps the blocks a
/// stage frees in its per-thread heaps, where the next stage's different sizes cannot always
/// reuse them: without this a whole run's peak grows with its length although each stage
/// alone stays flat. Called between stages and every few parts; other C libraries have
/// nothing to do here.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: malloc_trim only returns free memory to the system; it is thread-safe.
        unsafe {
            malloc_trim(0);
        }
    }
}

/// Sets glibc's allocator for how a run uses memory: a part of a thousand waveforms (88 MB
/// in 12.6 KB vectors on a forest's 3152-bin gate) is allocated by the workers and freed by
/// the writer, part after part. By default free() gives the top of a thread's heap back to
/// the system as soon as 128 KiB lie free there, so every part would fault the same pages in
/// again (a large share of a long-gate simulate stage's CPU time spent in the kernel), and a
/// block above a threshold that adapts from 128 KiB comes from mmap, one by one. Both
/// thresholds are raised (the mmap one to its largest, 32 MiB); freed memory still goes back
/// between stages and every few parts ([`release_after_part`]). Other C libraries: nothing.
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn mallopt(param: i32, value: i32) -> i32;
        }
        const M_TRIM_THRESHOLD: i32 = -1;
        const M_MMAP_THRESHOLD: i32 = -3;
        // SAFETY: mallopt only sets allocator parameters; it is called before any thread
        // starts, and a value it refuses leaves the default in place.
        unsafe {
            mallopt(M_MMAP_THRESHOLD, 32 << 20);
            mallopt(M_TRIM_THRESHOLD, 256 << 20);
        }
    }
}

/// Parts handled between two calls of [`release_free_memory`] in a stage's loop.
const RELEASE_EVERY_PARTS: usize = 16;

/// [`release_free_memory`] after every [`RELEASE_EVERY_PARTS`]-th part a loop has handled
/// (`n` counts from 0): fragments of freed parts would otherwise pile up over a long campaign.
pub fn release_after_part(n: usize) {
    if n % RELEASE_EVERY_PARTS == RELEASE_EVERY_PARTS - 1 {
        release_free_memory();
    }
}

/// Peak resident memory of this process since it started or since the last
/// [`reset_peak_rss`], bytes (Linux: VmHWM of /proc/self/status; None elsewhere).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// When a stage started, by the wall clock and by the process CPU clock.
#[derive(Clone, Copy, Debug)]
pub struct StageClock {
    pub wall: std::time::Instant,
    pub cpu: Option<f64>,
}

impl StageClock {
    pub fn start() -> StageClock {
        StageClock {
            wall: std::time::Instant::now(),
            cpu: process_cpu_seconds(),
        }
    }

    /// Wall time since the start, s.
    pub fn wall_s(&self) -> f64 {
        self.wall.elapsed().as_secs_f64()
    }

    /// Process CPU time since the start, all threads, s (None without a CPU clock).
    pub fn cpu_s(&self) -> Option<f64> {
        self.cpu.zip(process_cpu_seconds()).map(|(a, b)| b - a)
    }

    /// ", CPU x % of y %" for the stage, `secs` of wall time since the start: the share of
    /// the cores it kept busy. Empty without a CPU clock.
    pub fn busy(&self, secs: f64) -> String {
        self.cpu_s()
            .map(|cpu| {
                let threads = rayon::current_num_threads();
                format!(
                    ", CPU {:.0} % of {} %",
                    100.0 * cpu / secs.max(1e-9),
                    100 * threads
                )
            })
            .unwrap_or_default()
    }
}

/// CPU time of this process so far, user and system, all threads, s: the process CPU clock,
/// to the nanosecond (/proc/self/stat counts 10 ms ticks, coarse against a stage of a few
/// tenths of a second), else /proc/self/stat's ticks; None where neither exists.
pub fn process_cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut t = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes the one timespec it is given, which lives through the
        // call
        if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) } == 0 {
            return Some(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9);
        }
    }
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // the command name (field 2) may hold spaces: count fields after its closing parenthesis
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11);
    let user: f64 = fields.next()?.parse().ok()?;
    let system: f64 = fields.next()?.parse().ok()?;
    Some((user + system) / 100.0)
}

/// Resets the peak-memory mark to the current resident size, so that each measured piece of
/// work reports its own peak (Linux >= 4.0: writing 5 to clear_refs).
pub fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

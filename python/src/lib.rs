//! `lidarsim._lidarsim`: the library's API for the Python package (python/lidarsim/), and
//! nothing else. Every call goes to the same functions the CLI calls; this crate only moves
//! values across: campaigns and mappings in as JSON text (a subset of YAML), tables out
//! through the Arrow C stream interface, arrays out as bytes numpy wraps without a copy,
//! errors out as the package's exception classes.

use arrow_array::ffi_stream::FFI_ArrowArrayStream;
use arrow_array::{RecordBatch, RecordBatchIterator};
use arrow_schema::SchemaRef;
use lidarsim::campaign::Doc;
use lidarsim::error::Kind;
use lidarsim::pipeline::{self, open::RunFolder, RunOptions, Stage};
use lidarsim::plan::OnePulse;
use lidarsim::transport::Scratch;
use lidarsim::waveform::record::Recorder;
use lidarsim::waveform::Waveform;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyCapsule, PyDict, PyList};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::{mpsc, Arc, Mutex, OnceLock};
use std::time::Duration;

/// How often a run waiting in Python looks at the interpreter's signals.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// The package's exception for a lidarsim error: `lidarsim.errors.InputError`, `IoError`,
/// `DataError` (each a `LidarsimError`), with the error's place and advice as attributes.
fn to_py(py: Python<'_>, e: &lidarsim::Error) -> PyErr {
    let class = match e.kind {
        Kind::Input => "InputError",
        Kind::Io => "IoError",
        Kind::Data => "DataError",
        Kind::Interrupted(_) => "LidarsimError",
    };
    let made = (|| -> PyResult<PyErr> {
        let module = py.import("lidarsim.errors")?;
        let err = module.getattr(class)?.call1((e.to_string(),))?;
        let path = |p: &Option<PathBuf>| p.as_ref().map(|p| p.display().to_string());
        err.setattr("file", path(&e.file))?;
        err.setattr("line", e.line)?;
        err.setattr("column", e.column)?;
        err.setattr("key", e.key.clone())?;
        err.setattr("advice", e.advice.clone())?;
        Ok(PyErr::from_value(err))
    })();
    made.unwrap_or_else(|why| why)
}

/// An exception raised for an error in the text `label` names (a mapping's campaign, made
/// JSON by the package) without its file, line and column: the caller has no such file.
fn unplaced(py: Python<'_>, e: PyErr, label: Option<&std::path::Path>) -> PyErr {
    let Some(label) = label else {
        return e;
    };
    let v = e.value(py);
    let named = v
        .getattr("file")
        .ok()
        .and_then(|f| f.extract::<Option<String>>().ok())
        .flatten()
        .is_some_and(|f| std::path::Path::new(&f) == label);
    if !named {
        return e;
    }
    let text = v.str().map(|s| s.to_string()).unwrap_or_default();
    let prefix = label.display().to_string();
    // `label:line:col: key: message` less its place
    let rest = text
        .strip_prefix(&prefix)
        .map(|r| {
            r.trim_start_matches(|c: char| c.is_ascii_digit() || c == ':')
                .trim_start()
        })
        .unwrap_or(&text)
        .to_string();
    let made = (|| -> PyResult<PyErr> {
        let err = v.get_type().call1((rest,))?;
        for (name, keep) in [
            ("file", false),
            ("line", false),
            ("column", false),
            ("key", true),
            ("advice", true),
        ] {
            let value = if keep {
                v.getattr(name)?
            } else {
                py.None().into_bound(py)
            };
            err.setattr(name, value)?;
        }
        Ok(PyErr::from_value(err))
    })();
    made.unwrap_or(e)
}

/// Runs `f`, turning its error into the package's exception and a panic into a
/// `LidarsimError` (never a Rust panic across into Python).
fn guarded<T>(py: Python<'_>, f: impl FnOnce() -> lidarsim::Result<T>) -> PyResult<T> {
    settle(py, catch_unwind(AssertUnwindSafe(f)))
}

/// `f` with the interpreter released (other Python threads go on), guarded as [`guarded`].
fn detached<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> lidarsim::Result<T> + Send,
) -> PyResult<T> {
    settle(py, py.detach(|| catch_unwind(AssertUnwindSafe(f))))
}

/// Runs `f` on a thread of its own while this one polls the interpreter's signals every
/// [`SIGNAL_POLL`]; on the first, `on_signal` asks the work to stop (at its boundary), and once
/// it has, the signal's exception (KeyboardInterrupt) is what comes back. Otherwise, what `f`
/// came to, panics caught.
fn polled<T: Send>(
    py: Python<'_>,
    what: &str,
    on_signal: fn(),
    f: impl FnOnce() -> lidarsim::Result<T> + Send,
) -> PyResult<std::thread::Result<lidarsim::Result<T>>> {
    let (tx, rx) = mpsc::channel();
    // (a receiver is not shared between threads: the lock only lends it to the wait)
    let rx = Mutex::new(rx);
    std::thread::scope(|s| {
        s.spawn(move || {
            let _ = tx.send(catch_unwind(AssertUnwindSafe(f)));
        });
        let mut stopped: Option<PyErr> = None;
        loop {
            let got = py.detach(|| {
                let rx = rx.lock().unwrap_or_else(|e| e.into_inner());
                rx.recv_timeout(SIGNAL_POLL)
            });
            match got {
                Ok(r) => return stopped.map_or(Ok(r), Err),
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if let Err(e) = py.check_signals() {
                        if stopped.is_none() {
                            on_signal();
                            stopped = Some(e);
                        }
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err(format!(
                        "the {what}'s thread ended without a word"
                    )))
                }
            }
        }
    })
}

/// [`detached`] for work that may run long on its own (a pulse of many rays): on Ctrl-C the
/// work drops what is left of it (`interrupt::abandon`) and KeyboardInterrupt is raised once
/// it has.
fn interruptible<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> lidarsim::Result<T> + Send,
) -> PyResult<T> {
    lidarsim::interrupt::clear_abandon();
    let r = polled(py, "pulse", lidarsim::interrupt::abandon, f);
    lidarsim::interrupt::clear_abandon();
    settle(py, r?)
}

/// What a guarded call came to, as Python sees it: its value, the package's exception for
/// its error, or a `LidarsimError` for a panic (a bug, not the user's input).
fn settle<T>(py: Python<'_>, r: std::thread::Result<lidarsim::Result<T>>) -> PyResult<T> {
    match r {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py(py, &e)),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic".into());
            let message = format!("internal error (please report): {what}");
            let made = py
                .import("lidarsim.errors")
                .and_then(|m| m.getattr("LidarsimError"))
                .and_then(|c| c.call1((message,)));
            Err(made.map_or_else(|why| why, PyErr::from_value))
        }
    }
}

/// A YAML value from JSON text the package wrote (which checks its numbers first: what is
/// left to fail here is an argument's, an InputError).
fn value(json: &str) -> PyResult<serde_yaml::Value> {
    serde_yaml::from_str(json).map_err(|e| {
        Python::attach(|py| to_py(py, &lidarsim::Error::msg(format!("not a value: {e}"))))
    })
}

/// A table handed over once through the Arrow C stream interface (the PyCapsule protocol:
/// pyarrow takes it with `RecordBatchReader.from_stream`, with no copy).
#[pyclass(module = "lidarsim._lidarsim")]
struct ArrowStream {
    table: Option<(SchemaRef, Vec<RecordBatch>)>,
}

#[pymethods]
impl ArrowStream {
    #[pyo3(signature = (requested_schema=None))]
    fn __arrow_c_stream__<'py>(
        &mut self,
        py: Python<'py>,
        requested_schema: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyCapsule>> {
        // the schema is the table's own: a requested one is left to pyarrow to cast to
        let _ = requested_schema;
        let (schema, batches) = self
            .table
            .take()
            .ok_or_else(|| PyRuntimeError::new_err("this table was already taken"))?;
        let reader = RecordBatchIterator::new(batches.into_iter().map(Ok), schema);
        let stream = FFI_ArrowArrayStream::new(Box::new(reader));
        PyCapsule::new_with_value(py, stream, c"arrow_array_stream")
    }
}

fn stream(table: (SchemaRef, Vec<RecordBatch>)) -> ArrowStream {
    ArrowStream { table: Some(table) }
}

fn batch(b: RecordBatch) -> ArrowStream {
    stream((b.schema(), vec![b]))
}

/// A 1-D array's bytes (little-endian f64), for numpy to wrap.
fn f64_bytes<'py>(py: Python<'py>, v: impl Iterator<Item = f64>) -> Bound<'py, PyByteArray> {
    let bytes: Vec<u8> = v.flat_map(f64::to_le_bytes).collect();
    PyByteArray::new(py, &bytes)
}

fn f32_bytes<'py>(py: Python<'py>, v: &[f32]) -> Bound<'py, PyByteArray> {
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    PyByteArray::new(py, &bytes)
}

/// The crate's version.
#[pyfunction]
fn version() -> &'static str {
    lidarsim::VERSION
}

/// Runs a campaign (a file, or a mapping's JSON text named `label`) into its run folder and
/// returns the run's summary. Waits with the interpreter released, looking at its signals
/// every 50 ms: on Ctrl-C the run stops at its next part boundary, and the KeyboardInterrupt
/// is raised once it has.
#[pyfunction]
#[pyo3(signature = (path=None, text=None, label=None, out=None, threads=None, resume=false, stages=None, shard=None, overrides=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    path: Option<PathBuf>,
    text: Option<String>,
    label: Option<PathBuf>,
    out: Option<PathBuf>,
    threads: Option<usize>,
    resume: bool,
    stages: Option<Vec<String>>,
    shard: Option<(usize, usize)>,
    overrides: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let overrides: Vec<(String, serde_yaml::Value)> = match overrides {
        Some(json) => match value(&json)? {
            serde_yaml::Value::Mapping(m) => m
                .into_iter()
                .map(|(k, v)| (k.as_str().unwrap_or_default().to_string(), v))
                .collect(),
            _ => Vec::new(),
        },
        None => Vec::new(),
    };
    // a mapping's campaign has no file: its errors name the key alone, not a place in the
    // JSON text the package made of it
    let text_label = text
        .as_ref()
        .map(|_| label.clone().unwrap_or_else(|| PathBuf::from("campaign")));
    let loaded = guarded(py, || {
        let doc = match (&path, text) {
            (Some(p), _) => {
                if !p.is_file() {
                    return Err(lidarsim::campaign::missing_campaign(p));
                }
                Doc::read(p)?
            }
            (None, Some(text)) => Doc {
                path: label.unwrap_or_else(|| PathBuf::from("campaign")),
                text,
            },
            (None, None) => return Err(lidarsim::Error::msg("no campaign given")),
        };
        lidarsim::plan::load_campaign(doc, &overrides)
    })
    .map_err(|e| unplaced(py, e, text_label.as_deref()))?;
    // an argument's error names the argument, as the package's own checks do
    let named = |key: &'static str| move |e: lidarsim::Error| e.for_key(key);
    let opts = guarded(py, || {
        if let Some(n) = threads.filter(|&n| n == 0 || n > pipeline::MAX_THREADS) {
            return Err(lidarsim::Error::msg(format!(
                "expected 1 to {} threads, found {n}",
                pipeline::MAX_THREADS
            ))
            .for_key("threads"));
        }
        Ok(RunOptions {
            out,
            threads,
            resume,
            stages: stages
                .map(|v| v.iter().map(|s| Stage::from_name(s)).collect())
                .transpose()
                .map_err(named("stages"))?,
            shard: shard
                .map(pipeline::check_shard)
                .transpose()
                .map_err(named("shard"))?,
        })
    })?;
    lidarsim::interrupt::clear();
    // on Ctrl-C the run finishes the part in hand, writes it and ends
    let result = polled(
        py,
        "run",
        || lidarsim::interrupt::request(2),
        || pipeline::run_loaded(&loaded, &opts),
    )?;
    let s = settle(py, result).map_err(|e| unplaced(py, e, text_label.as_deref()))?;
    let d = PyDict::new(py);
    // as a path, not as text: a folder whose name is not UTF-8 comes back as itself
    d.set_item("out", &s.out)?;
    d.set_item("pulses", s.pulses)?;
    d.set_item("rays", s.rays)?;
    d.set_item("seconds", s.seconds)?;
    d.set_item("parts_done", s.parts_done)?;
    d.set_item("complete", s.complete)?;
    Ok(d)
}

/// `lidarsim check`'s report as JSON text.
#[pyfunction]
fn check(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    detached(py, || {
        if !path.is_file() {
            return Err(lidarsim::Error::file(&path, "campaign file does not exist"));
        }
        let report = pipeline::check::check(&path)?;
        serde_json::to_string(&report).map_err(|e| lidarsim::Error::msg(e.to_string()))
    })
}

/// `lidarsim compare`'s table (the columns of `--csv`), runs and sweeps expanded.
#[pyfunction]
fn compare(py: Python<'_>, runs: Vec<PathBuf>) -> PyResult<ArrowStream> {
    detached(py, || {
        Ok(batch(lidarsim::compare::table(&lidarsim::compare::rows(
            &runs,
        )?)))
    })
}

/// Reads one table or text of a run folder: `what` is pulses, waveforms, points, photons,
/// campaign (JSON text), manifest, report.
#[pyfunction]
#[pyo3(signature = (folder, what, pulse_ids=None))]
fn read_run<'py>(
    py: Python<'py>,
    folder: PathBuf,
    what: &str,
    pulse_ids: Option<Vec<u64>>,
) -> PyResult<Bound<'py, PyAny>> {
    enum Got {
        Table(ArrowStream),
        Text(String),
        Yaml(serde_yaml::Value),
    }
    let got = detached(py, || {
        let run = RunFolder::open(&folder)?;
        Ok(match what {
            "pulses" => Got::Table(stream(run.pulses()?)),
            "waveforms" => Got::Table(stream(run.waveforms(pulse_ids.as_deref())?)),
            "points" => Got::Table(batch(run.points()?)),
            "photons" => Got::Table(stream(run.photons()?)),
            "campaign" => Got::Yaml(run.campaign()?),
            "manifest" => Got::Text(run.manifest_json()?),
            "report" => Got::Text(run.text("report.md", "report")?),
            other => return Err(lidarsim::Error::msg(format!("no table named {other:?}"))),
        })
    })?;
    Ok(match got {
        Got::Table(t) => Bound::new(py, t)?.into_any(),
        Got::Text(t) => t.into_pyobject(py)?.into_any(),
        Got::Yaml(v) => yaml_to_py(py, &v)?,
    })
}

/// A YAML value as Python's YAML readers give it: mappings as dicts whose number keys stay
/// numbers (`{532.0: 0.12}`), sequences as lists, null as None.
fn yaml_to_py<'py>(py: Python<'py>, v: &serde_yaml::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_yaml::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(u)) => u.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Sequence(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(yaml_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Mapping(m) => {
            let d = PyDict::new(py);
            for (k, v) in m {
                // a key Python cannot hash (a list or mapping, which no campaign has) as text
                let key = match k {
                    Value::Sequence(_) | Value::Mapping(_) => lidarsim::campaign::yaml::inline(k)
                        .into_pyobject(py)?
                        .into_any(),
                    k => yaml_to_py(py, k)?,
                };
                d.set_item(key, yaml_to_py(py, v)?)?;
            }
            d.into_any()
        }
        Value::Tagged(t) => yaml_to_py(py, &t.value)?,
    })
}

/// The DSM rasters of a run: name → (cells as float32 bytes, height, width, geotransform,
/// EPSG code or None).
#[pyfunction]
fn read_dsm<'py>(py: Python<'py>, folder: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let r = detached(py, || RunFolder::open(&folder)?.dsm())?;
    let d = PyDict::new(py);
    for (name, raster) in [
        ("dsm", &r.dsm),
        ("reference", &r.reference),
        ("difference", &r.difference),
    ] {
        d.set_item(
            name,
            (
                f32_bytes(py, &raster.values),
                raster.height,
                raster.width,
                raster.transform.to_vec(),
                raster.epsg,
            ),
        )?;
    }
    Ok(d)
}

/// The CLI, with these arguments (the first is the program's name); returns its exit code.
#[pyfunction]
fn cli_main(py: Python<'_>, argv: Vec<String>) -> i32 {
    // a command's lines go to its terminal, as the Rust binary's do
    lidarsim::progress::set_sink(None);
    py.detach(|| {
        catch_unwind(|| lidarsim::cli::main_with(argv)).unwrap_or_else(|_| {
            eprintln!("error: internal error (please report)");
            1
        })
    })
}

/// A box's lowest and highest corners.
type Corners = ((f64, f64, f64), (f64, f64, f64));

/// A scene loaded once (its BVHs built) for many single pulses; loaded again for bands it
/// was not loaded at, and kept.
#[pyclass(name = "Scene", module = "lidarsim._lidarsim", frozen)]
struct PyScene {
    path: PathBuf,
    loaded: Mutex<Vec<(Vec<u64>, Arc<lidarsim::scene::Scene>)>>,
    /// The tracer's buffers, reused from call to call.
    scratch: Mutex<Scratch>,
}

impl PyScene {
    fn at(&self, py: Python<'_>, bands: &[f64]) -> PyResult<Arc<lidarsim::scene::Scene>> {
        let key: Vec<u64> = bands.iter().map(|w| w.to_bits()).collect();
        if let Some((_, s)) = self
            .loaded
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .find(|(k, _)| *k == key)
        {
            return Ok(Arc::clone(s));
        }
        let path = self.path.clone();
        let bands = bands.to_vec();
        let scene = Arc::new(detached(py, || {
            lidarsim::scene::Scene::load_bands(&path, &bands)
        })?);
        self.loaded
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((key, Arc::clone(&scene)));
        Ok(scene)
    }
}

#[pymethods]
impl PyScene {
    /// Loads a scene file at the given bands (default: a wavelength every material gives).
    #[staticmethod]
    #[pyo3(signature = (path, wavelengths_nm=None))]
    fn load(py: Python<'_>, path: PathBuf, wavelengths_nm: Option<Vec<f64>>) -> PyResult<Self> {
        let bands = match wavelengths_nm {
            Some(b) => b,
            None => vec![guarded(py, || {
                lidarsim::scene::Scene::common_wavelength(&path)
            })?],
        };
        let s = PyScene {
            path,
            loaded: Mutex::new(Vec::new()),
            scratch: Mutex::new(Scratch::default()),
        };
        s.at(py, &bands)?;
        Ok(s)
    }

    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    /// ((xmin, ymin, zmin), (xmax, ymax, zmax)), metres.
    #[getter]
    fn bounds(&self, py: Python<'_>) -> PyResult<Corners> {
        let first = self
            .loaded
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .first()
            .map(|(_, s)| Arc::clone(s));
        let scene = match first {
            Some(s) => s,
            None => self.at(py, &[1064.0])?,
        };
        let (lo, hi) = scene.bounds();
        Ok(((lo.x, lo.y, lo.z), (hi.x, hi.y, hi.z)))
    }

    /// One pulse of a one-pulse static campaign over this scene (JSON texts: the campaign's
    /// sections); a list of dicts, one per band, each with the waveform's arrays as bytes.
    #[pyo3(signature = (instrument, origin, direction, wavelength_nm, simulation, seed, sun=None, atmosphere=None, record=false))]
    #[allow(clippy::too_many_arguments)]
    fn simulate_pulse<'py>(
        &self,
        py: Python<'py>,
        instrument: &str,
        origin: [f64; 3],
        direction: [f64; 3],
        wavelength_nm: &str,
        simulation: &str,
        seed: u64,
        sun: Option<&str>,
        atmosphere: Option<&str>,
        record: bool,
    ) -> PyResult<Bound<'py, PyList>> {
        let request = OnePulse {
            instrument: value(instrument)?,
            origin,
            direction,
            wavelength_nm: value(wavelength_nm)?,
            simulation: value(simulation)?,
            seed,
            sun: sun.map(value).transpose()?,
            atmosphere: atmosphere.map(value).transpose()?,
        };
        let (loaded, _) = guarded(py, || request.campaign(&self.path, "simulate_pulse"))?;
        let c = &loaded.campaign;
        let scene = self.at(py, c.wavelength_nm.all())?;
        let rows: Vec<Waveform> = interruptible(py, || {
            let mut own = Scratch::default();
            let mut held = self.scratch.try_lock().ok();
            let scratch = held.as_deref_mut().unwrap_or(&mut own);
            pipeline::simulate_in_memory(&loaded, &scene, scratch)
        })?;
        let recorder = record.then(|| Recorder::new(&c.instrument, c.seed));
        let out = PyList::empty(py);
        for w in &rows {
            let d = PyDict::new(py);
            let bins = w.impulse_energy_j.len();
            d.set_item("t0_ns", w.t0_ns)?;
            d.set_item("bin_ns", w.bin_ns as f64)?;
            d.set_item(
                "wavelength_nm",
                w.wavelength_nm.unwrap_or(c.wavelength_nm.first()),
            )?;
            d.set_item(
                "energy_j",
                f64_bytes(py, w.impulse_energy_j.iter().map(|&x| x as f64)),
            )?;
            d.set_item(
                "energy_se_j",
                f64_bytes(py, (0..bins).map(|b| w.impulse_se(b) as f64)),
            )?;
            d.set_item(
                "photons",
                f64_bytes(py, w.laser_photons.iter().map(|&x| x as f64)),
            )?;
            d.set_item(
                "order_energy_j",
                f64_bytes(py, w.order_energy_j.iter().copied()),
            )?;
            d.set_item(
                "order_energy_se_j",
                f64_bytes(py, w.order_energy_se_j.iter().copied()),
            )?;
            d.set_item("received_energy_j", w.received_energy_j)?;
            d.set_item("received_energy_se_j", w.received_energy_se_j)?;
            d.set_item("outside_gate_energy_j", w.outside_gate_energy_j)?;
            d.set_item("solar_photons_per_bin", w.solar_photons_per_bin as f64)?;
            d.set_item("rays", w.rays)?;
            if let Some(r) = &recorder {
                let rec = r.record(w);
                d.set_item(
                    "record",
                    f64_bytes(py, rec.samples.iter().map(|&x| x as f64)),
                )?;
                d.set_item("record_background", rec.background)?;
            }
            out.append(d)?;
        }
        Ok(out)
    }
}

/// Sends the library's log lines to Python's `logging` (logger "lidarsim"): warnings as
/// warnings, the rest as info.
fn log_to_python(line: &str) {
    static LOGGER: OnceLock<Py<PyAny>> = OnceLock::new();
    Python::attach(|py| {
        let logger = match LOGGER.get() {
            Some(l) => l.bind(py).clone(),
            None => {
                let Ok(l) = py
                    .import("logging")
                    .and_then(|m| m.call_method1("getLogger", ("lidarsim",)))
                else {
                    return;
                };
                let _ = LOGGER.set(l.clone().unbind());
                l
            }
        };
        let level = if line.starts_with("warning") {
            "warning"
        } else {
            "info"
        };
        let _ = logger.call_method1(level, (line,));
    });
}

#[pymodule]
fn _lidarsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    if let Some(why) = lidarsim::cli::unsupported_cpu() {
        return Err(pyo3::exceptions::PyImportError::new_err(why));
    }
    lidarsim::progress::set_sink(Some(Arc::new(log_to_python)));
    m.add("C", lidarsim::C)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(read_run, m)?)?;
    m.add_function(wrap_pyfunction!(read_dsm, m)?)?;
    m.add_function(wrap_pyfunction!(cli_main, m)?)?;
    m.add_class::<PyScene>()?;
    m.add_class::<ArrowStream>()?;
    Ok(())
}

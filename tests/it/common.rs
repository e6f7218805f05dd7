//! Helpers shared by the integration tests.

use glam::DVec3;
use pedscan::gpu::{Context, ContextOptions, DeviceChoice};
use pedscan::backend::raster::renderer::Renderer;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A Vulkan context with the Khronos validation layer on (its absence is a failure, not a skip).
pub fn context() -> Arc<Context> {
    let ctx = Context::new(&ContextOptions { validation: true, device: DeviceChoice::Auto })
        .expect("Vulkan context with validation (install vulkan-validationlayers, mesa-vulkan-drivers)");
    assert!(ctx.validation_enabled());
    Arc::new(ctx)
}

/// Drops renderer and context, then asserts the validation layer reported no error at all
/// (leaks are reported when the device is destroyed).
pub fn finish(renderer: Renderer, ctx: Arc<Context>) {
    let errors = ctx.validation_counter();
    drop(renderer);
    assert_eq!(Arc::strong_count(&ctx), 1, "the context outlives everything else");
    drop(ctx);
    assert_eq!(errors.load(Ordering::SeqCst), 0, "validation errors (see stderr)");
}

/// An axis-aligned box [lo, hi] as 12 triangles (each side its own 4 vertices), wound so the
/// normals point outward (`outward`) or inward. f64 positions (world or sensor frame).
pub fn box_f64(lo: DVec3, hi: DVec3, outward: bool) -> (Vec<DVec3>, Vec<u32>) {
    let centre = 0.5 * (lo + hi);
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    for axis in 0..3 {
        for side in [lo, hi] {
            let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |s1: bool, s2: bool| {
                let mut p = side;
                p[a1] = if s1 { hi[a1] } else { lo[a1] };
                p[a2] = if s2 { hi[a2] } else { lo[a2] };
                p
            };
            let quad = [corner(false, false), corner(true, false), corner(true, true), corner(false, true)];
            let n = (quad[1] - quad[0]).cross(quad[2] - quad[0]);
            let mut face_centre = centre;
            face_centre[axis] = side[axis];
            let out = n.dot(face_centre - centre) > 0.0;
            let base = pos.len() as u32;
            pos.extend_from_slice(&quad);
            let tris: [u32; 6] = if out == outward { [0, 1, 2, 0, 2, 3] } else { [0, 2, 1, 0, 3, 2] };
            idx.extend(tris.iter().map(|i| base + i));
        }
    }
    (pos, idx)
}

/// The bundled humans (`data/humans/*.glb`), in name order.
pub fn bundled_humans() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "glb"))
        .collect();
    v.sort();
    v
}

/// Runs the built `pedscan` binary in `dir`, as a user would, with the Vulkan validation
/// layer on.
pub fn pedscan(args: &[&str], dir: &Path) -> Output {
    pedscan_with_env(args, dir, &[])
}

/// [`pedscan`] with extra environment variables for the run.
pub fn pedscan_with_env(args: &[&str], dir: &Path, envs: &[(&str, &str)]) -> Output {
    command(args, dir, envs).output().expect("run pedscan")
}

/// The command line of a run of the built binary (see [`pedscan`]).
fn command(args: &[&str], dir: &Path, envs: &[(&str, &str)]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pedscan"));
    c.args(args).current_dir(dir).envs(envs.iter().copied());
    // The one place the runs of the binary get validation (a missing layer fails the run):
    // every command that can open a Vulkan device takes `--validation`.
    if matches!(args.first(), Some(&"generate") | Some(&"crosscheck") | Some(&"sheet")) {
        c.arg("--validation");
    }
    c
}

/// How long a bounded run or load may go on before it is taken for a hang and fails the test.
/// Generous on purpose: it catches a hang, never a slow or busy machine (speed is measured by
/// `pedscan bench` and whole processes timed in turn, A B A B, never asserted).
pub const HANG: Duration = Duration::from_secs(300);

/// The data-segment cap for runs that are to be refused as bad input: a refused run loads the
/// bundled people and hall and reads its inputs' headers, well under this; every case the
/// hostile tests make is caught by a reader or a bound before any large allocation (a glitched
/// pose once cost 7.4 GB).
pub const REFUSED_RUN_DATA_BYTES: u64 = 1 << 30;

/// [`pedscan`] under bounds that fail a test the same way on every machine: the run's data
/// segment (heap and private writable mappings, `RLIMIT_DATA`) is capped at `max_data_bytes`,
/// so an input that makes it allocate gigabytes aborts it however fast the machine is, and a
/// run still going after [`HANG`] is killed as hung.
pub fn pedscan_bounded(args: &[&str], dir: &Path, max_data_bytes: u64) -> Output {
    use std::os::unix::process::CommandExt;
    let mut c = command(args, dir, &[]);
    c.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    // SAFETY: setrlimit is async-signal-safe; the closure allocates nothing.
    unsafe {
        c.pre_exec(move || {
            let lim = libc::rlimit { rlim_cur: max_data_bytes as libc::rlim_t, rlim_max: max_data_bytes as libc::rlim_t };
            if libc::setrlimit(libc::RLIMIT_DATA, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut child = c.spawn().expect("start pedscan");
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            r.read_to_end(&mut v).ok();
            v
        })
    };
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let err = drain(Box::new(child.stderr.take().unwrap()));
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait for pedscan") {
            break s;
        }
        if t0.elapsed() > HANG {
            child.kill().ok();
            child.wait().ok();
            panic!("pedscan {args:?} still running after {HANG:?}: hung");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Output { status, stdout: out.join().unwrap(), stderr: err.join().unwrap() }
}

/// The integration tests' allocator: the system's, counting each thread's live bytes and their
/// peak, so [`bounded`] can bound what one call allocates without timing anything.
struct Counting;

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn note(delta: isize) {
    let _ = LIVE.try_with(|live| {
        let now = live.get() + delta;
        live.set(now);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
    });
}

// SAFETY: every call is forwarded to `System` unchanged; the counters are plain thread-locals
// with const initialisers (no allocation, no re-entry).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            note(layout.size() as isize);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            note(layout.size() as isize);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        note(-(layout.size() as isize));
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            note(new_size as isize - layout.size() as isize);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Runs `f` on a thread of its own and returns its result, failing the test if `f` allocates
/// more than `max_bytes` at its peak (live bytes of that thread) or is still running after
/// [`HANG`]. `what` names the call in the messages.
pub fn bounded<T: Send + 'static>(what: &str, max_bytes: usize, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        PEAK.with(|p| p.set(0));
        LIVE.with(|l| l.set(0));
        let value = f();
        let peak = PEAK.with(|p| p.get());
        tx.send((value, peak)).ok();
    });
    let (value, peak) = rx.recv_timeout(HANG).unwrap_or_else(|e| panic!("{what}: no answer after {HANG:?} ({e}): hung"));
    assert!(peak as usize <= max_bytes, "{what}: allocated {peak} bytes at its peak, more than {max_bytes}");
    value
}

/// Asserts that a run succeeded, showing its stderr when not.
pub fn ok(o: &Output) {
    assert!(o.status.success(), "pedscan failed ({:?}):\n{}", o.status.code(), String::from_utf8_lossy(&o.stderr));
}

/// Asserts that a run is refused as an input error (exit code 2) whose message names `needle`.
pub fn expect_input_error(args: &[&str], dir: &Path, needle: &str) {
    let o = pedscan(args, dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "exit code for {args:?}: {err}");
    assert!(err.contains(needle), "message for {args:?} should name `{needle}`: {err}");
}

/// The bounds themselves: an allocation over the cap fails the call, one under it passes, and
/// a child over its data cap dies instead of answering.
#[test]
fn bounded_calls_fail_over_their_allocation_cap() {
    assert_eq!(bounded("small", 1 << 20, || std::hint::black_box(vec![1u8; 1 << 10]).len()), 1 << 10);
    let over = std::panic::catch_unwind(|| bounded("large", 1 << 20, || std::hint::black_box(vec![1u8; 4 << 20]).len()));
    let msg = over.err().and_then(|e| e.downcast_ref::<String>().cloned()).expect("4 MiB against a 1 MiB cap fails");
    assert!(msg.contains("large: allocated") && msg.contains("more than 1048576"), "{msg}");
    let dir = tempfile::tempdir().unwrap();
    let o = pedscan_bounded(&["generate", "--out", "o", "--backend", "raycast", "--frames", "1"], dir.path(), 1 << 20);
    assert!(!o.status.success(), "a run in a 1 MiB data segment cannot load the bundled people");
}

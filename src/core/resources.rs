//! Lazy resources: files named by path, loaded on worker threads. A handle is Pending,
//! Ready or Failed; its version bumps whenever it (re)loads, which is what makes the
//! nodes that use it re-run. In watch mode, edited files are reloaded.

use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Why a resource has no value (yet).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LoadError {
    /// Still loading (or reloading after an error).
    #[error("{} is still loading", .0.display())]
    Pending(PathBuf),
    /// The load failed; the message names the file.
    #[error("{0}")]
    Failed(String),
}

type Loaded = Arc<dyn Any + Send + Sync>;
type LoadFn = Box<dyn Fn(&Path) -> anyhow::Result<Loaded> + Send + Sync>;

#[derive(Clone)]
pub enum SlotState {
    Pending,
    Ready(Loaded),
    Failed(String),
}

pub struct Slot {
    pub path: PathBuf,
    state: Mutex<SlotState>,
    version: AtomicU64,
    /// Loads requested so far, and the request whose result `state` holds: two loads of one
    /// file can run at once (two quick edits), and the older must not overwrite the newer.
    requested: AtomicU64,
    applied: AtomicU64,
    load: LoadFn,
}

pub type SlotRef = Arc<Slot>;

impl Slot {
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::Acquire)
    }
    pub fn state(&self) -> SlotState {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
}

struct Inner {
    slots: Mutex<HashMap<(PathBuf, TypeId), SlotRef>>,
    jobs: Mutex<Option<Sender<SlotRef>>>,
    in_flight: Mutex<usize>,
    idle: Condvar,
    watcher: Mutex<Option<notify::RecommendedWatcher>>,
    watched_dirs: Mutex<Vec<PathBuf>>,
}

/// The resource manager. Cheap to clone.
#[derive(Clone)]
pub struct Resources {
    inner: Arc<Inner>,
}

impl Resources {
    /// `watch`: reload files when they change on disk (interactive mode).
    pub fn new(watch: bool) -> Resources {
        let (tx, rx) = channel::<SlotRef>();
        let inner = Arc::new(Inner {
            slots: Mutex::new(HashMap::new()),
            jobs: Mutex::new(Some(tx)),
            in_flight: Mutex::new(0),
            idle: Condvar::new(),
            watcher: Mutex::new(None),
            watched_dirs: Mutex::new(Vec::new()),
        });
        let rx = Arc::new(Mutex::new(rx));
        let workers = std::thread::available_parallelism().map_or(2, |n| n.get()).clamp(1, 4);
        for i in 0..workers {
            let rx = rx.clone();
            let weak = Arc::downgrade(&inner);
            std::thread::Builder::new()
                .name(format!("werkstatt-loader-{i}"))
                .spawn(move || worker(rx, weak))
                .expect("cannot start a resource loader thread");
        }
        let resources = Resources { inner };
        if watch {
            resources.start_watcher();
        }
        resources
    }

    /// Returns the slot for `path` (starting its load the first time) and its current value.
    pub fn request<T: Send + Sync + 'static>(
        &self,
        path: &Path,
        loader: fn(&Path) -> anyhow::Result<T>,
    ) -> (SlotRef, Result<Arc<T>, LoadError>) {
        let (slot, _, value) = self.request_observed(path, loader);
        (slot, value)
    }

    /// Like [`Resources::request`], also returning the slot's version read *before* its value:
    /// a load that completes in between leaves an older version with a newer value, so a node
    /// that records this version re-runs once more instead of missing the load.
    pub fn request_observed<T: Send + Sync + 'static>(
        &self,
        path: &Path,
        loader: fn(&Path) -> anyhow::Result<T>,
    ) -> (SlotRef, u64, Result<Arc<T>, LoadError>) {
        let path = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        let key = (path.clone(), TypeId::of::<T>());
        let (slot, fresh) = {
            let mut slots = self.inner.slots.lock().unwrap_or_else(|e| e.into_inner());
            match slots.get(&key) {
                Some(s) => (s.clone(), false),
                None => {
                    let slot = Arc::new(Slot {
                        path: path.clone(),
                        state: Mutex::new(SlotState::Pending),
                        version: AtomicU64::new(0),
                        requested: AtomicU64::new(0),
                        applied: AtomicU64::new(0),
                        load: Box::new(move |p| loader(p).map(|v| Arc::new(v) as Loaded)),
                    });
                    slots.insert(key, slot.clone());
                    (slot, true)
                }
            }
        };
        if fresh {
            self.watch_dir(&path);
            self.enqueue(slot.clone());
        }
        let version = slot.version();
        let value = match slot.state() {
            SlotState::Pending => Err(LoadError::Pending(path)),
            SlotState::Failed(e) => Err(LoadError::Failed(e)),
            SlotState::Ready(v) => {
                v.downcast::<T>().map_err(|_| LoadError::Failed(format!("{}: loaded as another type", path.display())))
            }
        };
        (slot, version, value)
    }

    /// Forgets the resource `path` loaded as `T`, freeing its value, unless something else
    /// still holds its slot (a node that touched it in its last run, a loader working on it).
    /// Returns whether it is gone (or was never there).
    pub fn release<T: 'static>(&self, path: &Path) -> bool {
        let path = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        let key = (path, TypeId::of::<T>());
        let mut slots = self.inner.slots.lock().unwrap_or_else(|e| e.into_inner());
        match slots.get(&key) {
            Some(slot) if Arc::strong_count(slot) > 1 => false,
            _ => {
                slots.remove(&key);
                true
            }
        }
    }

    fn enqueue(&self, slot: SlotRef) {
        *self.inner.in_flight.lock().unwrap_or_else(|e| e.into_inner()) += 1;
        slot.requested.fetch_add(1, Ordering::AcqRel);
        if let Some(tx) = self.inner.jobs.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            let _ = tx.send(slot);
        }
    }

    /// Blocks until no load is in flight (batch mode, for deterministic output).
    pub fn wait_idle(&self) {
        let mut n = self.inner.in_flight.lock().unwrap_or_else(|e| e.into_inner());
        while *n > 0 {
            n = self.inner.idle.wait(n).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// `wait_idle` with a deadline: true once nothing is loading, false if loads are still in
    /// flight after `timeout` (a loader that hangs), so a caller can fail with a message.
    pub fn wait_idle_timeout(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut n = self.inner.in_flight.lock().unwrap_or_else(|e| e.into_inner());
        while *n > 0 {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            n = self.inner.idle.wait_timeout(n, left).unwrap_or_else(|e| e.into_inner()).0;
        }
        true
    }

    /// How many resources are held (loaded, loading or failed).
    pub fn resident(&self) -> usize {
        self.inner.slots.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    pub fn in_flight(&self) -> usize {
        *self.inner.in_flight.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Reloads every resource whose file is `path` (called by the watcher).
    pub fn reload(&self, path: &Path) {
        let slots: Vec<SlotRef> = self
            .inner
            .slots
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .values()
            .filter(|s| s.path == path || split_part(&s.path).0 == path)
            .cloned()
            .collect();
        for s in slots {
            self.enqueue(s);
        }
    }

    fn start_watcher(&self) {
        let weak = Arc::downgrade(&self.inner);
        let handler = move |event: notify::Result<notify::Event>| {
            let (Ok(event), Some(inner)) = (event, weak.upgrade()) else { return };
            // A removed file reloads too, so its node says the file is gone instead of showing
            // the last contents; editors that delete before writing reload again on create.
            if !(event.kind.is_modify() || event.kind.is_create() || event.kind.is_remove()) {
                return;
            }
            let me = Resources { inner };
            for p in &event.paths {
                me.reload(p);
            }
        };
        match notify::recommended_watcher(handler) {
            Ok(w) => *self.inner.watcher.lock().unwrap_or_else(|e| e.into_inner()) = Some(w),
            Err(e) => eprintln!("warning: cannot watch files for changes ({e}); edits on disk will not reload"),
        }
    }

    /// Watches the file's folder, not the file: editors save by replacing the file.
    fn watch_dir(&self, path: &Path) {
        use notify::Watcher;
        let mut guard = self.inner.watcher.lock().unwrap_or_else(|e| e.into_inner());
        let Some(watcher) = guard.as_mut() else { return };
        let Some(dir) = path.parent() else { return };
        let mut dirs = self.inner.watched_dirs.lock().unwrap_or_else(|e| e.into_inner());
        if dirs.iter().any(|d| d == dir) {
            return;
        }
        if watcher.watch(dir, notify::RecursiveMode::NonRecursive).is_ok() {
            dirs.push(dir.to_path_buf());
        }
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        // Closing the channel ends the workers.
        self.jobs.lock().unwrap_or_else(|e| e.into_inner()).take();
    }
}

/// A resource that is one part of a file (a frame of an Alembic cache): `<file>|<part>`. It
/// reloads with its file, and a missing file is reported as such. `part` must not hold `|` or
/// a path separator.
pub fn part_path(file: &Path, part: &str) -> PathBuf {
    debug_assert!(!part.contains(['|', '/', '\\']), "a resource part holds no | or separator");
    let mut s = file.as_os_str().to_owned();
    s.push("|");
    s.push(part);
    PathBuf::from(s)
}

/// The file and part of a [`part_path`]; a plain path is its own file.
pub fn split_part(path: &Path) -> (&Path, Option<&str>) {
    match path.to_str().and_then(|s| s.rsplit_once('|')) {
        Some((file, part)) => (Path::new(file), Some(part)),
        None => (path, None),
    }
}

/// Whether a path parameter names a file sequence (frame_%04d.obj, frame_####.obj,
/// frame_*.obj) rather than one file.
pub fn is_file_pattern(path: &str) -> bool {
    path.contains(['%', '#', '*'])
}

fn worker(rx: Arc<Mutex<Receiver<SlotRef>>>, inner: std::sync::Weak<Inner>) {
    loop {
        let job = {
            let rx = rx.lock().unwrap_or_else(|e| e.into_inner());
            rx.recv()
        };
        let Ok(slot) = job else { return };
        // Every request up to this one was made before the file is read here.
        let request = slot.requested.load(Ordering::Acquire);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (slot.load)(&slot.path)));
        // Say plainly that the file is missing: loaders word it their own way ("open file
        // failed"). A sequence pattern never exists as such; its loader explains what matched.
        let file = split_part(&slot.path).0;
        let missing = !slot.path.exists() && !file.exists() && !is_file_pattern(&file.to_string_lossy());
        let state = match result {
            Ok(Err(_)) if missing => SlotState::Failed(format!("no such file: {}", file.display())),
            Ok(Ok(v)) => SlotState::Ready(v),
            Ok(Err(e)) => SlotState::Failed(format!("{}: {e:#}", slot.path.display())),
            Err(_) => SlotState::Failed(format!("{}: the loader crashed on this file", slot.path.display())),
        };
        {
            let mut current = slot.state.lock().unwrap_or_else(|e| e.into_inner());
            // A load that read the file after this one did has already landed: keep it.
            if request >= slot.applied.load(Ordering::Acquire) {
                *current = state;
                slot.applied.store(request, Ordering::Release);
                slot.version.fetch_add(1, Ordering::AcqRel);
            }
        }
        let Some(inner) = inner.upgrade() else { return };
        let mut n = inner.in_flight.lock().unwrap_or_else(|e| e.into_inner());
        *n = n.saturating_sub(1);
        inner.idle.notify_all();
    }
}

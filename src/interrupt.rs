//! Ctrl-C (SIGINT) and SIGTERM during a solve. [`Guard::install`] replaces the handlers of both by
//! one that only sets a flag, which the solve polls after every step
//! ([`StopOn`](crate::output::StopOn) -> [`ReturnCode::Interrupted`](crate::solve::ReturnCode)), so
//! the run ends with whole, partial outputs. Dropping the last guard restores the previous handlers:
//! a host process (Python calling [`crate::cli::run`]) gets its own back. A signal ignored when the
//! guard is installed stays ignored (a background job of a non-interactive shell). A second signal
//! while the first is pending takes the default action (the way out of a step that does not end).

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// Handlers of SIGINT and SIGTERM replaced while it lives (nested guards share one installation).
pub struct Guard {
    released: bool,
}

impl Guard {
    /// Install the handlers (once for nested guards) and clear the flag.
    pub fn install() -> Guard {
        imp::install(&REQUESTED, &SIGNAL);
        Guard { released: false }
    }

    /// Set by the first SIGINT or SIGTERM since the installation.
    pub fn flag(&self) -> &'static AtomicBool {
        &REQUESTED
    }

    /// The signal that set the flag, if any.
    pub fn signal(&self) -> Option<i32> {
        match SIGNAL.load(Ordering::SeqCst) {
            0 => None,
            s => Some(s),
        }
    }

    /// Drop the guard and say which signal it caught, when this was the last guard (the previous
    /// handlers are back) and a signal came: the caller hands it on to them with [`raise`] once it
    /// has kept what was computed (a host process, Python, then runs its own handler: a
    /// KeyboardInterrupt). None while an outer guard still holds the handlers.
    pub fn release(mut self) -> Option<i32> {
        self.released = true;
        let restored = imp::uninstall();
        restored.then(|| self.signal()).flatten()
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        if !self.released {
            imp::uninstall();
        }
    }
}

/// Deliver `sig` to this process again, to the handler now installed (after [`Guard::release`]).
pub fn raise(sig: i32) {
    imp::raise(sig);
}

/// Ignore SIGXFSZ for the rest of the process (the `progmo` binary calls it first): a write past
/// the file size limit (`ulimit -f`) then fails with EFBIG, which the outputs report as a write
/// error (exit 3, files left as `.partial`), instead of the signal killing the process mid-write.
/// Python ignores it already.
pub fn ignore_file_size_signal() {
    #[cfg(unix)]
    // SAFETY: sets a disposition to SIG_IGN; no handler runs.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

#[cfg(unix)]
mod imp {
    use super::{REQUESTED, SIGNAL};
    use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
    use std::sync::Mutex;

    struct Installed {
        depth: usize,
        /// The handlers replaced, to put back.
        saved: Vec<(libc::c_int, libc::sigaction)>,
    }

    static STATE: Mutex<Installed> = Mutex::new(Installed {
        depth: 0,
        saved: Vec::new(),
    });

    /// Async-signal-safe: atomics, and for a second signal signal(2) and raise(3).
    extern "C" fn on_signal(sig: libc::c_int) {
        if REQUESTED.swap(true, Ordering::SeqCst) {
            // SAFETY: both are async-signal-safe.
            unsafe {
                libc::signal(sig, libc::SIG_DFL);
                libc::raise(sig);
            }
            return;
        }
        SIGNAL.store(sig, Ordering::SeqCst);
    }

    pub(super) fn install(flag: &AtomicBool, signal: &AtomicI32) {
        let mut st = STATE.lock().unwrap_or_else(|e| e.into_inner());
        st.depth += 1;
        if st.depth > 1 {
            return;
        }
        flag.store(false, Ordering::SeqCst);
        signal.store(0, Ordering::SeqCst);
        let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        for sig in [libc::SIGINT, libc::SIGTERM] {
            // SAFETY: sigaction with valid pointers; the handler only touches atomics.
            unsafe {
                let mut old: libc::sigaction = std::mem::zeroed();
                if libc::sigaction(sig, std::ptr::null(), &mut old) != 0
                    || old.sa_sigaction == libc::SIG_IGN
                {
                    continue;
                }
                let mut new: libc::sigaction = std::mem::zeroed();
                new.sa_sigaction = handler;
                libc::sigemptyset(&mut new.sa_mask);
                new.sa_flags = libc::SA_RESTART;
                if libc::sigaction(sig, &new, &mut old) == 0 {
                    st.saved.push((sig, old));
                }
            }
        }
    }

    /// Uninstall one guard; true when this restored the previous handlers (the last guard).
    pub(super) fn uninstall() -> bool {
        let mut st = STATE.lock().unwrap_or_else(|e| e.into_inner());
        st.depth = st.depth.saturating_sub(1);
        if st.depth > 0 {
            return false;
        }
        for (sig, old) in st.saved.drain(..) {
            // SAFETY: restores a disposition sigaction returned.
            unsafe {
                libc::sigaction(sig, &old, std::ptr::null_mut());
            }
        }
        true
    }

    pub(super) fn raise(sig: libc::c_int) {
        // SAFETY: raise(3) with a signal number the handler received.
        unsafe {
            libc::raise(sig);
        }
    }
}

#[cfg(not(unix))]
mod imp {
    use std::sync::atomic::{AtomicBool, AtomicI32};

    pub(super) fn install(_flag: &AtomicBool, _signal: &AtomicI32) {}
    pub(super) fn uninstall() -> bool {
        true
    }
    pub(super) fn raise(_sig: i32) {}
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// The tests share the process's handlers: one at a time.
    static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

    fn handler_of(sig: libc::c_int) -> libc::sighandler_t {
        // SAFETY: query only.
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            assert_eq!(libc::sigaction(sig, std::ptr::null(), &mut old), 0);
            old.sa_sigaction
        }
    }

    #[test]
    fn a_signal_sets_the_flag_and_the_previous_handler_comes_back() {
        // SIGTERM only: the test harness keeps SIGINT for the user.
        let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let before = handler_of(libc::SIGTERM);
        {
            let g = Guard::install();
            assert!(!g.flag().load(Ordering::SeqCst));
            {
                let inner = Guard::install();
                drop(inner);
            }
            assert_ne!(handler_of(libc::SIGTERM), before, "nested guard kept it");
            // SAFETY: our handler is installed; it only sets the flag.
            unsafe { libc::raise(libc::SIGTERM) };
            assert!(g.flag().load(Ordering::SeqCst));
            assert_eq!(g.signal(), Some(libc::SIGTERM));
        }
        assert_eq!(handler_of(libc::SIGTERM), before);
    }

    #[test]
    fn release_names_the_signal_only_when_the_handlers_are_back() {
        let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let before = handler_of(libc::SIGTERM);
        let outer = Guard::install();
        let inner = Guard::install();
        // SAFETY: our handler is installed; it only sets the flag.
        unsafe { libc::raise(libc::SIGTERM) };
        assert_eq!(
            inner.release(),
            None,
            "an outer guard still holds the handlers"
        );
        assert_ne!(handler_of(libc::SIGTERM), before);
        assert_eq!(outer.release(), Some(libc::SIGTERM));
        assert_eq!(handler_of(libc::SIGTERM), before);
    }
}

//! SIGINT and SIGTERM during a fit: instead of ending the process, a signal sets a flag that
//! the fit reads after every accepted iterate; it then writes its checkpoint and the results
//! so far and exits with `128 + the signal's number` (130, 143). Further signals only set the
//! flag again, so nothing interrupts the writing (SIGKILL still does; the results stay
//! consistent as a set, [`crate::results`]).

use crate::error::CliError;
use signal_hook::consts::{SIGINT, SIGTERM};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

/// The termination signals a fit catches.
pub struct Signals {
    /// The number of the last signal received, 0 before any.
    received: Arc<AtomicUsize>,
}

/// A signal that stopped a fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Signal(i32);

impl Signal {
    /// Its name, `SIGINT` or `SIGTERM`.
    pub fn name(self) -> &'static str {
        match self.0 {
            SIGINT => "SIGINT",
            SIGTERM => "SIGTERM",
            _ => "a signal",
        }
    }

    /// The exit code of a process it ended: `128 + n`.
    pub fn exit_code(self) -> u8 {
        u8::try_from(128 + self.0).unwrap_or(u8::MAX)
    }
}

impl Signals {
    /// Catches SIGINT and SIGTERM from now on (for the rest of the process).
    pub fn catch() -> Result<Self, CliError> {
        let received = Arc::new(AtomicUsize::new(0));
        for signal in [SIGINT, SIGTERM] {
            let number = usize::try_from(signal).unwrap_or_default();
            signal_hook::flag::register_usize(signal, Arc::clone(&received), number)
                .map_err(|e| CliError::io(std::path::Path::new("<signal handler>"), e))?;
        }
        Ok(Self { received })
    }

    /// The last signal received, if any.
    pub fn received(&self) -> Option<Signal> {
        match self.received.load(Ordering::SeqCst) {
            0 => None,
            n => Some(Signal(i32::try_from(n).unwrap_or(SIGTERM))),
        }
    }
}

/// Makes SIGXFSZ harmless for the rest of the process: a write beyond the file-size limit
/// (`ulimit -f`) then fails with `EFBIG` ("File too large"), which ends the command with a
/// one-line error naming the file (its temporary file removed, the earlier file intact),
/// instead of the signal killing the process mid-write (issue 33). A handler that does
/// nothing is installed (it survives nothing the signal's default would not: an ignored
/// signal and a caught one both make the write fail instead).
pub fn survive_file_size_limit() -> Result<(), CliError> {
    #[cfg(unix)]
    {
        let flag = Arc::new(std::sync::atomic::AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGXFSZ, flag)
            .map_err(|e| CliError::Input(format!("cannot handle SIGXFSZ: {e}")))?;
    }
    Ok(())
}

//! `--executor mpi` on the command line: MPI is initialised before anything is written, so
//! every rank knows whether it is rank 0, the only one that writes outputs and prints.

use anyhow::Result;
use soda::sim::{ExecutorKind, RunOptions};

/// This process's part in a run: rank 0 of an MPI job or any run without MPI writes and
/// prints; the other ranks compute only. Holds the MPI session (finalised when dropped).
pub struct Role {
    root: bool,
    #[cfg(feature = "mpi")]
    _session: Option<soda::exec::mpi::Session>,
}

impl Role {
    /// The role of this process in a run with `options` (initialises MPI for an MPI run).
    pub fn of(options: &RunOptions) -> Result<Self> {
        Self::under_mpi(options.executor == ExecutorKind::Mpi)
    }

    /// The role of this process in a command that runs under `mpirun` if `mpi` (initialises
    /// MPI then), or alone.
    pub fn under_mpi(mpi: bool) -> Result<Self> {
        #[cfg(feature = "mpi")]
        if mpi {
            let session = soda::exec::mpi::Session::init()?;
            return Ok(Role {
                root: session.is_root(),
                _session: Some(session),
            });
        }
        #[cfg(not(feature = "mpi"))]
        if mpi {
            anyhow::bail!("{}", soda::exec::error::MpiError::NotBuilt);
        }
        Ok(Role {
            root: true,
            #[cfg(feature = "mpi")]
            _session: None,
        })
    }

    /// Whether this process writes the outputs and prints the summary.
    pub fn root(&self) -> bool {
        self.root
    }
}

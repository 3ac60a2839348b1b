//! A cohort: many subjects fitted from one template into one folder, `DIR/SUBJECT/` each, by
//! `medial batch`. [`subjects`] reads and checks the subject table (SUBJECTS.csv), [`shard`]
//! chooses the subjects of one job of many, [`gather`] tabulates the fits that finished
//! (`cohort.csv`, `thickness.npy`, the mean thickness on the template's medial sheet) and
//! [`slurm`] writes the scripts that run a cohort as a Slurm job array.

pub mod gather;
pub mod shard;
pub mod slurm;
pub mod subjects;

/// The names `medial batch` writes in the cohort folder itself; no subject may be called so.
pub const RESERVED: [&str; 8] = [
    gather::COHORT_CSV,
    gather::THICKNESS_NPY,
    gather::THICKNESS_SUBJECTS,
    gather::THICKNESS_MEAN,
    slurm::BATCH_SCRIPT,
    slurm::GATHER_SCRIPT,
    slurm::SUBMIT_SCRIPT,
    slurm::LOG_FOLDER,
];

/// The file in a subject's folder that records a fit that did not succeed: `subject`, `error`
/// (the one-line message) and `exit_code` (what `medial fit` would have exited with).
pub const FAILED_JSON: &str = "failed.json";

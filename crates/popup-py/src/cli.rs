//! `run_cli`: the Rust CLI (`popup_cli::run_from_args`) for the Python package's `popup`
//! command, which routes every subcommand it does not implement in Python here.

use pyo3::prelude::*;

/// Run the Rust `popup` CLI on a full argument vector (`argv[0]` is the program name) and
/// return its exit code. Prints to the process's stdout/stderr (file descriptors 1 and 2,
/// not `sys.stdout`); runs without the GIL. A panic (e.g. stdout closed under `println!`)
/// is reported by the panic hook and returns 101, the exit code of a panicking binary.
#[pyfunction]
pub fn run_cli(py: Python<'_>, argv: Vec<String>) -> i32 {
    py.detach(move || {
        std::panic::catch_unwind(move || popup_cli::run_from_args(argv)).unwrap_or(101)
    })
}

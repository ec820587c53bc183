//! The integration tests of `cli`, one test binary (each module was a test binary of its own).

mod cli_field;
mod cli_path_cost;
mod import_cli;
mod paper_numbers;

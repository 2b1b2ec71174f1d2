//! The code of the `wisplight` and `wisplight-bench` programs: the only
//! code that touches the terminal, parses arguments and turns errors into
//! messages and exit codes. `wisplight` renders, serves and coordinates
//! workers, views and exports (`cmd`); `wisplight-bench` measures
//! (`bench`), and `wisplight bench ...` runs it.

#![recursion_limit = "256"]
// The programs' modules are public only for their two binaries: their
// users' documentation is each command's --help, not rustdoc.
#![allow(missing_docs)]

pub mod app;
pub mod bench;
pub mod cli;
pub mod cmd;
pub mod csv;
pub mod cycles;
pub mod output;

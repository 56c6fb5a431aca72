//! Lines for the terminal that never panic.
//!
//! `println!` and `eprintln!` panic when the stream is a pipe whose reader went away
//! (`ipc-runner eval … | head -3`): the command then died in the middle, before the files it
//! had yet to write. These write the line if they can, and otherwise drop it: the command
//! goes on (its files, its exit status); only the reader that left misses lines. Every
//! binary of the workspace prints through them (`channel-sim`, `ipc-runner` and its
//! subcommands; the bridge has its own, having no dependency on this crate).

/// `print!` to stdout that drops the text when stdout cannot take it.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        let _ = ::std::write!(::std::io::stdout().lock(), $($arg)*);
    }};
}

/// `println!` to stdout that drops the line when stdout cannot take it.
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        let _ = ::std::writeln!(::std::io::stdout().lock(), $($arg)*);
    }};
}

/// `eprintln!` that drops the line when stderr cannot take it.
#[macro_export]
macro_rules! errln {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        let _ = ::std::writeln!(::std::io::stderr().lock(), $($arg)*);
    }};
}

#[cfg(test)]
mod tests {
    /// The macros format like `println!` (checked through a closed pipe in tests/hostile_cli).
    #[test]
    fn they_expand_and_format() {
        crate::out!("{}", "");
        crate::outln!("{} {:.1}", "x", 1.25);
        crate::errln!("{:?}", [1, 2]);
    }
}

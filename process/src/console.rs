//! Lines for the terminal that never panic.
//!
//! `println!` and `eprintln!` panic when the stream is a pipe whose reader went away
//! (`ipc-runner eval … | head -3`): the command then died in the middle, before the files it
//! had yet to write. These write the line if they can, and otherwise drop it: the command
//! goes on (its files, its exit status); only the reader that left misses lines. Every
//! binary of the workspace prints through them (`channel-sim`, `ipc-runner` and its
//! subcommands, the bridge).

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

/// `message` as one printable line: line breaks and tabs become spaces, any other control
/// character its escape (`\u{1b}`). Error messages quote what came from outside (a file's
/// text, a publisher's scenario name, a `--prefix`), which must neither split the one error
/// line nor send escape sequences to the terminal.
pub fn one_line(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    for c in message.chars() {
        match c {
            '\n' | '\r' | '\t' => out.push(' '),
            c if c.is_control() => out.extend(c.escape_default()),
            c => out.push(c),
        }
    }
    out
}

/// iceoryx2's log level from `IOX2_LOG_LEVEL` (fatal, error, warn, info, debug, trace, any
/// case; `error` when unset). A value it does not know is one warning line naming `binary`,
/// and `error`: iceoryx2's own parser printed four lines for it.
pub fn set_iceoryx2_log_level(binary: &str) {
    use iceoryx2::prelude::LogLevel;
    let level = match std::env::var_os("IOX2_LOG_LEVEL") {
        None => LogLevel::Error,
        Some(v) => match log_level(&v.to_string_lossy()) {
            Some(l) => l,
            None => {
                crate::errln!(
                    "{binary}: warning: IOX2_LOG_LEVEL={} is none of fatal, error, warn, info, \
                     debug, trace; using error",
                    one_line(&format!("{v:?}"))
                );
                LogLevel::Error
            }
        },
    };
    iceoryx2::prelude::set_log_level(level);
}

fn log_level(v: &str) -> Option<iceoryx2::prelude::LogLevel> {
    use iceoryx2::prelude::LogLevel;
    Some(match v.trim().to_lowercase().as_str() {
        "trace" => LogLevel::Trace,
        "debug" => LogLevel::Debug,
        "info" => LogLevel::Info,
        "warn" => LogLevel::Warn,
        "error" => LogLevel::Error,
        "fatal" => LogLevel::Fatal,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn log_levels_are_iceoryx2s_names_in_any_case() {
        use iceoryx2::prelude::LogLevel;
        assert!(matches!(super::log_level("Error"), Some(LogLevel::Error)));
        assert!(matches!(super::log_level(" TRACE "), Some(LogLevel::Trace)));
        assert!(super::log_level("garbage").is_none());
        assert!(super::log_level("").is_none());
    }

    #[test]
    fn one_line_keeps_text_and_defuses_control_characters() {
        assert_eq!(super::one_line("a α 'b' \\"), "a α 'b' \\");
        assert_eq!(
            super::one_line("no subscriber on a\nb/slots\x1b[31m\u{7f}"),
            "no subscriber on a b/slots\\u{1b}[31m\\u{7f}"
        );
    }

    /// The macros format like `println!` (checked through a closed pipe in tests/hostile_cli).
    #[test]
    fn they_expand_and_format() {
        crate::out!("{}", "");
        crate::outln!("{} {:.1}", "x", 1.25);
        crate::errln!("{:?}", [1, 2]);
    }
}

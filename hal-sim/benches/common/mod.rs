//! What the benchmarks share: reading their settings from the environment.

/// The number in the environment variable `key` when it parses and `ok` accepts it; its
/// `default` when the variable is not set. A bad value gets one message naming the key, the
/// value and what is `expected`, and the default is used.
pub fn env_number<T: std::str::FromStr + std::fmt::Display + Copy>(
    key: &str,
    default: T,
    ok: impl Fn(&T) -> bool,
    expected: &str,
) -> T {
    match std::env::var(key) {
        Ok(s) => match s.trim().parse::<T>() {
            Ok(v) if ok(&v) => v,
            _ => {
                eprintln!("{key}={s:?}: {expected} expected; {default} used");
                default
            }
        },
        Err(std::env::VarError::NotPresent) => default,
        Err(std::env::VarError::NotUnicode(_)) => {
            eprintln!("{key}: not valid text; {expected} expected; {default} used");
            default
        }
    }
}

//! Phase tracing of long builds.

/// With `TESSERA_TRACE` set, prints `what` to standard error with the seconds since the first
/// call and the process's major page faults so far (from `/proc/self/stat`): where a build in
/// a memory limit pages, phase by phase (docs/design.md, "Spilling").
pub fn trace(what: &str) {
    use std::sync::OnceLock;
    static START: OnceLock<Option<std::time::Instant>> = OnceLock::new();
    let Some(start) = START.get_or_init(|| std::env::var_os("TESSERA_TRACE").map(|_| std::time::Instant::now())) else {
        return;
    };
    // Field 12 of /proc/self/stat, counted after the command's closing parenthesis.
    let majflt = std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| s.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().nth(9).map(str::to_owned)))
        .unwrap_or_default();
    eprintln!("trace {:8.2} s {majflt:>9} major faults: {what}", start.elapsed().as_secs_f64());
}

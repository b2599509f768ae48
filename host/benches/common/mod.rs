//! Shared by the bench binaries: the CPU time this process has used, so figures can be given
//! per CPU second on a machine whose wall clock is shared with other work.

/// User plus system CPU seconds of this process (Linux `/proc/self/stat`); `None` elsewhere.
pub fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    // Clock ticks; 100 per second on every Linux configuration in use.
    Some((utime + stime) / 100.0)
}

//! `--serve` of the timing examples (`graph_timing`, `render_timing`): the timed runs asked for
//! on standard input, so that a comparison script can alternate them with its own
//! (`bench/timing.py`'s `Served` and `alternated`).

use std::error::Error;
use std::io::{BufRead, Write};
use std::time::Instant;

/// The runs asked for on standard input: a line `N [WARM_SECONDS]` asks for untimed runs for
/// WARM_SECONDS (at least one), then N timed ones, whose seconds (as `run` returns them) are
/// printed as one JSON line `{key: [...]}`. All the timed ones, at the end of the input.
pub fn served<E: Error + 'static>(
    key: &str,
    mut run: impl FnMut() -> Result<f64, E>,
) -> Result<Vec<f64>, Box<dyn Error>> {
    let mut all = Vec::new();
    let mut stdout = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let line = line?;
        let wrong = || format!("--serve: a line holds {line:?}, not `N [WARM_SECONDS]`");
        let mut fields = line.split_whitespace();
        let count: usize = fields
            .next()
            .and_then(|n| n.parse().ok())
            .ok_or_else(wrong)?;
        let warm = match fields.next() {
            Some(seconds) => seconds
                .parse::<f64>()
                .ok()
                .filter(|s| s.is_finite() && *s >= 0.0),
            None => Some(0.0),
        }
        .ok_or_else(wrong)?;
        let started = Instant::now();
        run()?;
        while started.elapsed().as_secs_f64() < warm {
            run()?;
        }
        let runs = (0..count).map(|_| run()).collect::<Result<Vec<f64>, E>>()?;
        writeln!(stdout, "{}", serde_json::json!({ key: runs }))?;
        stdout.flush()?;
        all.extend(runs);
    }
    if all.is_empty() {
        return Err("--serve: no timed run was asked for".into());
    }
    Ok(all)
}

//! Checks that a screenshot (PNG) shows a page rather than a blank or broken one: prints its
//! size, the fraction of non-white pixels and the number of distinct colours, and exits with
//! failure when the page looks blank. Used by `scripts/check-report-renders.sh`.
//!
//! Usage: `cargo run -p imucal --example png_stats -- SHOT.png [MIN_INK_FRACTION] [MIN_COLOURS]`

use std::process::ExitCode;

/// Pixels whose every channel is at least this bright count as background.
const WHITE_LEVEL: u8 = 245;

fn stats(path: &str) -> Result<(u32, u32, f64, usize), String> {
    let file = std::fs::File::open(path).map_err(|e| format!("cannot open `{path}`: {e}"))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("`{path}` is not a PNG image: {e}"))?;
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buffer)
        .map_err(|e| format!("`{path}` could not be decoded: {e}"))?;
    let channels = info.color_type.samples();
    let pixels = buffer.get(..info.buffer_size()).unwrap_or_default();
    let mut colours = std::collections::HashSet::new();
    let mut ink = 0usize;
    let mut total = 0usize;
    for pixel in pixels.chunks_exact(channels) {
        let rgb: Vec<u8> = match channels {
            1 | 2 => vec![pixel[0]; 3],
            _ => pixel[..3].to_vec(),
        };
        total += 1;
        if rgb.iter().any(|c| *c < WHITE_LEVEL) {
            ink += 1;
        }
        // Quantised to 4 bits per channel: anti-aliasing shades do not inflate the count.
        colours.insert((rgb[0] >> 4, rgb[1] >> 4, rgb[2] >> 4));
    }
    Ok((
        info.width,
        info.height,
        ink as f64 / total.max(1) as f64,
        colours.len(),
    ))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: png_stats SHOT.png [MIN_INK_FRACTION] [MIN_COLOURS]");
        return ExitCode::FAILURE;
    };
    let min_ink: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.02);
    let min_colours: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(8);
    match stats(path) {
        Ok((width, height, ink, colours)) => {
            println!(
                "{path}: {width}x{height}, non-white {:.1} %, {colours} distinct colours",
                ink * 100.0
            );
            if ink < min_ink || colours < min_colours {
                eprintln!(
                    "{path} looks blank: non-white {:.2} % (need {:.2} %), {colours} colours (need {min_colours})",
                    ink * 100.0,
                    min_ink * 100.0
                );
                return ExitCode::FAILURE;
            }
            ExitCode::SUCCESS
        }
        Err(message) => {
            eprintln!("{message}");
            ExitCode::FAILURE
        }
    }
}

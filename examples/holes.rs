//! Step a tissue and print its holes as they open and close: the library's core loop, without
//! files. A hole is a void region (Σφ < 0.01) larger than πR²/4, followed from frame to frame.
//!
//!   cargo run --release --example holes              # the page's persistent-hole tissue, 80²
//!   cargo run --release --example holes -- paper     # the paper's 140² tissue (minutes)
//!
//! The reduced tissue (33 cells on 80², χ = 0.001, ζ = 2.5) opens its first hole about 1,200
//! active steps after its 1,500-step relaxation; the paper's (100 cells on 140², ζ = 0.5) a few
//! thousand steps after its 10,000.

use monolayer::analysis::{Analysis, HoleTracker};
use monolayer::{Monolayer, Params};

/// Steps between looks at the tissue (a frame).
const FRAME: u64 = 250;

/// The tissue of `which`: "paper", or the page's persistent-hole preset.
fn params(which: &str) -> Params {
    match which {
        "paper" => Params { active_steps: 20_000, ..Params::default() },
        _ => Params {
            box_size: 80,
            n_cells: 33,
            zeta: 2.5,
            relax_steps: 1_500,
            active_steps: 2_500,
            ..Params::default()
        },
    }
}

/// Steps the tissue of `p` to its end, printing each hole's birth and end; returns the holes.
fn follow(p: Params, seed: u64) -> Result<usize, Box<dyn std::error::Error>> {
    let mut m = Monolayer::new(p.clone(), seed)?;
    m.advance(p.relax_steps)?;
    let mut analysis = Analysis::new(&p);
    let mut tracker = HoleTracker::new(p.radius);
    while m.step_count() < p.total_steps() {
        m.advance(FRAME)?;
        // Velocities belong to the last step's evaluation: measure them for this φ.
        m.evaluate_now()?;
        analysis.measure(&m);
        let open_before: Vec<usize> = tracker.open().map(|h| h.id).collect();
        tracker.update(&analysis.voids, m.step_count() as f64 * p.dt);
        for h in tracker.nucleated_holes() {
            let (_, area, x, y) = tracker.holes[h].history[0];
            println!("step {:>6}: hole {h} opens at ({x:.0}, {y:.0}), {area} sites", m.step_count());
        }
        for id in open_before {
            if tracker.holes[id].closed.is_some() {
                println!("step {:>6}: hole {id} {}", m.step_count(), tracker.holes[id].fate());
            }
        }
    }
    let open: Vec<String> =
        tracker.open().map(|h| format!("{} ({} sites)", h.id, h.history.last().unwrap().1)).collect();
    println!(
        "{} holes in all; open at the end: {}",
        tracker.holes.len(),
        if open.is_empty() { "none".into() } else { open.join(", ") }
    );
    Ok(tracker.holes.len())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let which = std::env::args().nth(1).unwrap_or_default();
    follow(params(&which), 1)?;
    Ok(())
}

#[test]
fn the_reduced_tissue_opens_a_hole() {
    assert!(follow(params(""), 1).unwrap() >= 1);
}

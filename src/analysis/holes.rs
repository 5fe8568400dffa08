//! Holes in the monolayer (paper Sec. A and Fig. 3, docs/reading.md §6).
//!
//! A site is void where Σ_i φ_i < 0.01. Void sites that touch (4-connected, across the periodic
//! edges) form a region. A hole nucleates when a region exceeds πR²/4 sites (a quarter of a cell)
//! and is then followed from frame to frame until no void site is left of it: a hole that shrinks
//! below πR²/4 is still open (the threshold decides birth, not death), so that a hole hovering
//! near the threshold is not counted as many.
//!
//! Frame to frame, a region continues the holes whose previous regions it overlaps (shares a
//! site with), or failing that the hole whose last centroid lies within a cell radius. A hole
//! whose region breaks in two keeps its identity in the larger part; a part that is itself above
//! the nucleation threshold becomes a new hole (`split_from`). Holes whose regions join continue
//! as the oldest of them; the others close (`merged_into`). For lifetimes, [`counted_holes`]
//! counts a hole with its fragments and the holes that joined it ([`HoleCounting`]).

/// A site is void below this Σφ (paper Sec. A).
pub const VOID_THRESHOLD: f64 = 0.01;
/// A site is covered at or above this Σφ (the packing fraction counts these).
pub const COVERED_THRESHOLD: f64 = 0.5;
const NONE: u32 = u32::MAX;

/// One connected void region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoidRegion {
    /// Number of void sites (area in lattice units).
    pub area: usize,
    /// Centroid on the periodic box (the region unwrapped about its first site, then wrapped).
    pub x: f64,
    pub y: f64,
}

/// The void regions of one frame: a label per site (or none) and the regions, with reusable
/// buffers.
#[derive(Clone, Debug, Default)]
pub struct VoidRegions {
    pub l: usize,
    /// Region index per site, `u32::MAX` where covered.
    pub labels: Vec<u32>,
    pub regions: Vec<VoidRegion>,
    /// Fraction of sites with Σφ ≥ ½.
    pub packing_fraction: f64,
    /// Fraction of void sites.
    pub void_fraction: f64,
    stack: Vec<(i64, i64)>,
}

impl VoidRegions {
    /// Labels the void regions of Σφ on the L×L lattice.
    pub fn find(&mut self, phi_sum: &[f64], l: usize) {
        self.l = l;
        self.labels.clear();
        self.labels.resize(l * l, NONE);
        self.regions.clear();
        let li = l as i64;
        let void = |i: usize| phi_sum[i] < VOID_THRESHOLD;
        for start in 0..l * l {
            if !void(start) || self.labels[start] != NONE {
                continue;
            }
            let label = self.regions.len() as u32;
            self.labels[start] = label;
            self.stack.clear();
            self.stack.push(((start % l) as i64, (start / l) as i64));
            let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
            while let Some((x, y)) = self.stack.pop() {
                n += 1;
                sx += x as f64;
                sy += y as f64;
                for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    let (nx, ny) = (x + dx, y + dy);
                    let j = (ny.rem_euclid(li) * li + nx.rem_euclid(li)) as usize;
                    if void(j) && self.labels[j] == NONE {
                        self.labels[j] = label;
                        self.stack.push((nx, ny));
                    }
                }
            }
            let wrapf = |v: f64| v.rem_euclid(l as f64);
            self.regions.push(VoidRegion { area: n, x: wrapf(sx / n as f64), y: wrapf(sy / n as f64) });
        }
        let n = (l * l) as f64;
        self.packing_fraction = phi_sum.iter().filter(|&&s| s >= COVERED_THRESHOLD).count() as f64 / n;
        self.void_fraction = self.regions.iter().map(|r| r.area).sum::<usize>() as f64 / n;
    }

    /// Regions larger than `threshold` sites: holes by the nucleation criterion alone.
    pub fn count_above(&self, threshold: f64) -> usize {
        self.regions.iter().filter(|r| r.area as f64 > threshold).count()
    }
}

/// The nucleation threshold πR²/4 (in sites) for cells of radius R.
pub fn nucleation_area(radius: f64) -> f64 {
    std::f64::consts::PI * radius * radius / 4.0
}

/// One hole from nucleation to closure.
#[derive(Clone, Debug, PartialEq)]
pub struct Hole {
    pub id: usize,
    /// Time of the first frame in which it was seen open.
    pub nucleated: f64,
    /// Time of the first frame in which it was gone (None while open).
    pub closed: Option<f64>,
    /// (time, area in sites, centroid x, centroid y) for every frame it was open.
    pub history: Vec<(f64, usize, f64, f64)>,
    /// The hole it broke off from, if it did.
    pub split_from: Option<usize>,
    /// The hole it joined when it closed by merging, if it did.
    pub merged_into: Option<usize>,
}

impl Hole {
    /// closed − nucleated, or None while open.
    pub fn lifetime(&self) -> Option<f64> {
        self.closed.map(|c| c - self.nucleated)
    }

    pub fn max_area(&self) -> usize {
        self.history.iter().map(|h| h.1).max().unwrap_or(0)
    }

    /// Why it closed: "closed", "merged", or "open".
    pub fn fate(&self) -> &'static str {
        match (self.closed, self.merged_into) {
            (None, _) => "open",
            (Some(_), Some(_)) => "merged",
            (Some(_), None) => "closed",
        }
    }
}

/// Follows holes from frame to frame.
#[derive(Clone, Debug)]
pub struct HoleTracker {
    /// Sites, in area, above which a new region is a hole.
    pub nucleation_area: f64,
    /// Centroids closer than this (periodic) match when regions do not overlap.
    pub match_distance: f64,
    /// Every hole ever seen, in order of nucleation.
    pub holes: Vec<Hole>,
    /// The previous frame's labels and the hole (index into `holes`) of each previous region.
    prev_labels: Vec<u32>,
    prev_hole: Vec<Option<usize>>,
    l: usize,
    pairs: Vec<(u32, u32)>,
}

impl HoleTracker {
    /// A tracker for cells of radius R: nucleation above πR²/4, matching within R.
    ///
    /// ```
    /// use monolayer::analysis::{Analysis, HoleTracker};
    /// use monolayer::{Monolayer, Params};
    ///
    /// let p = Params { box_size: 40, n_cells: 8, relax_steps: 100, ..Params::default() };
    /// let mut m = Monolayer::new(p.clone(), 1)?;
    /// let (mut a, mut holes) = (Analysis::new(&p), HoleTracker::new(p.radius));
    /// for _ in 0..2 {
    ///     m.advance(50)?;
    ///     a.measure(&m);
    ///     holes.update(&a.voids, m.step_count() as f64 * p.dt);
    /// }
    /// // Early in relaxation the seeded disks do not yet cover the box: the gap between them is
    /// // larger than πR²/4, so it counts as a hole, followed from its first frame.
    /// let first = holes.holes[0].history[0];
    /// assert!(first.1 as f64 > std::f64::consts::PI * p.radius * p.radius / 4.0);
    /// # Ok::<(), monolayer::SimError>(())
    /// ```
    pub fn new(radius: f64) -> Self {
        HoleTracker {
            nucleation_area: nucleation_area(radius),
            match_distance: radius,
            holes: Vec::new(),
            prev_labels: Vec::new(),
            prev_hole: Vec::new(),
            l: 0,
            pairs: Vec::new(),
        }
    }

    /// The holes open now.
    pub fn open(&self) -> impl Iterator<Item = &Hole> {
        self.holes.iter().filter(|h| h.closed.is_none())
    }

    /// The regions (indices into the last frame's [`VoidRegions::regions`]) that nucleated a hole
    /// in the last update: new holes, not fragments split off an open one.
    pub fn nucleated_regions(&self) -> impl Iterator<Item = usize> + '_ {
        self.prev_hole.iter().enumerate().filter_map(move |(r, h)| {
            let h = &self.holes[(*h)?];
            (h.history.len() == 1 && h.split_from.is_none() && h.closed.is_none()).then_some(r)
        })
    }

    /// The holes (indices into `holes`) that nucleated in the last update, as
    /// [`Self::nucleated_regions`].
    pub fn nucleated_holes(&self) -> impl Iterator<Item = usize> + '_ {
        self.prev_hole.iter().flatten().copied().filter(move |&h| {
            let h = &self.holes[h];
            h.history.len() == 1 && h.split_from.is_none() && h.closed.is_none()
        })
    }

    /// Whether lattice site `site` lies in a void region of the last frame that holds an open
    /// hole: a site that has torn already.
    pub fn in_open_hole(&self, site: usize) -> bool {
        self.prev_labels.get(site).is_some_and(|&r| r != NONE && self.prev_hole[r as usize].is_some())
    }

    /// Per region of the last frame (indexed by its label), whether it holds an open hole.
    pub fn open_regions(&self) -> Vec<bool> {
        self.prev_hole.iter().map(Option::is_some).collect()
    }

    /// Whether a hole family ([`HoleCounting::Families`]) with a member that ever grew above
    /// `area` sites is still open: Fig. 2's exclusion, "if a hole grows above a threshold size
    /// … lattice sites are not counted … until the hole closes". The hole closes when the
    /// family does (no member open), not when its area falls back below the threshold.
    pub fn large_family_open(&self, area: f64) -> bool {
        let root = family_roots(&self.holes);
        let mut large = vec![false; self.holes.len()];
        let mut open = vec![false; self.holes.len()];
        for (h, &r) in self.holes.iter().zip(&root) {
            large[r] |= h.max_area() as f64 > area;
            open[r] |= h.closed.is_none();
        }
        large.iter().zip(&open).any(|(&l, &o)| l && o)
    }

    /// Takes the void regions of the next frame, at time `time`: each region claims the holes it
    /// overlaps (or, failing any overlap, the nearest open hole within `match_distance`), each
    /// hole continues in the largest region that claims it, and the holes no region continues
    /// close.
    pub fn update(&mut self, voids: &VoidRegions, time: f64) {
        if self.l != voids.l {
            assert!(self.prev_labels.is_empty(), "the lattice size changed between frames");
            self.l = voids.l;
        }
        let open: Vec<usize> = (0..self.holes.len()).filter(|&h| self.holes[h].closed.is_none()).collect();
        let mut claims = self.claims_by_overlap(voids);
        self.claim_by_centroid(voids, &open, &mut claims);
        let (region_hole, continued) = self.continue_holes(voids, &claims, time);
        for &h in &open {
            if !continued[h] {
                self.holes[h].closed = Some(time);
            }
        }
        self.prev_labels.clone_from(&voids.labels);
        self.prev_hole = region_hole;
    }

    /// The holes each of this frame's regions overlaps (sites it shares with the previous
    /// frame's regions that were holes).
    fn claims_by_overlap(&mut self, voids: &VoidRegions) -> Vec<Vec<usize>> {
        self.pairs.clear();
        if !self.prev_labels.is_empty() {
            for (cur, prev) in voids.labels.iter().zip(&self.prev_labels) {
                if *cur != NONE && *prev != NONE && self.prev_hole[*prev as usize].is_some() {
                    self.pairs.push((*cur, *prev));
                }
            }
        }
        self.pairs.sort_unstable();
        self.pairs.dedup();
        let mut claims: Vec<Vec<usize>> = vec![Vec::new(); voids.regions.len()];
        for &(cur, prev) in &self.pairs {
            if let Some(h) = self.prev_hole[prev as usize] {
                if !claims[cur as usize].contains(&h) {
                    claims[cur as usize].push(h);
                }
            }
        }
        claims
    }

    /// Open holes that no region overlaps: each is claimed by the nearest unclaimed region within
    /// `match_distance` of its last centroid, if there is one.
    fn claim_by_centroid(&self, voids: &VoidRegions, open: &[usize], claims: &mut [Vec<usize>]) {
        for &h in open {
            if claims.iter().any(|c| c.contains(&h)) {
                continue;
            }
            let &(_, _, hx, hy) = self.holes[h].history.last().expect("an open hole has a history");
            let best = (0..voids.regions.len())
                .filter(|&r| claims[r].is_empty())
                .map(|r| (periodic_distance(hx, hy, voids.regions[r].x, voids.regions[r].y, voids.l), r))
                .filter(|&(d, _)| d <= self.match_distance)
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((_, r)) = best {
                claims[r].push(h);
            }
        }
    }

    /// Each hole continues in the largest region that claims it; of several holes claiming one
    /// region (a merge) the oldest goes on and the others close; an unclaimed region larger than
    /// `nucleation_area` is a new hole. Returns each region's hole and which holes went on.
    fn continue_holes(
        &mut self,
        voids: &VoidRegions,
        claims: &[Vec<usize>],
        time: f64,
    ) -> (Vec<Option<usize>>, Vec<bool>) {
        let nr = voids.regions.len();
        let mut region_hole: Vec<Option<usize>> = vec![None; nr];
        let mut continued = vec![false; self.holes.len()];
        let mut order: Vec<usize> = (0..nr).collect();
        order.sort_by(|&a, &b| voids.regions[b].area.cmp(&voids.regions[a].area).then(a.cmp(&b)));
        for &r in &order {
            let region = voids.regions[r];
            let mut live: Vec<usize> = claims[r].iter().copied().filter(|&h| !continued[h]).collect();
            live.sort_unstable();
            if let Some(&keep) = live.first() {
                continued[keep] = true;
                region_hole[r] = Some(keep);
                self.holes[keep].history.push((time, region.area, region.x, region.y));
                for &other in &live[1..] {
                    continued[other] = true;
                    self.holes[other].closed = Some(time);
                    self.holes[other].merged_into = Some(self.holes[keep].id);
                }
            } else if region.area as f64 > self.nucleation_area {
                // Nucleation, or a large fragment of a hole that split.
                let split_from = claims[r].first().map(|&h| self.holes[h].id);
                let id = self.holes.len();
                self.holes.push(Hole {
                    id,
                    nucleated: time,
                    closed: None,
                    history: vec![(time, region.area, region.x, region.y)],
                    split_from,
                    merged_into: None,
                });
                continued.push(true);
                region_hole[r] = Some(id);
            }
        }
        (region_hole, continued)
    }
}

/// How holes are counted for their lifetimes (the survival fit of the paper's Fig. 3c–d). The
/// tracker follows every void region; the paper does not say what a region that breaks off an
/// open hole, or one that opens beside it and joins it, counts as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HoleCounting {
    /// A hole is a family: the region that nucleated it, the fragments that break off it (and
    /// theirs), and the holes that join it. It lives from the first nucleation in the family
    /// until no member is open. The paper's reading (its "only one hole can form at a time, \[so\]
    /// long lifetimes prevent new ones from forming"), and the one the regime criterion uses.
    Families,
    /// Every tracked region is a hole of its own: a fragment above the nucleation area is born
    /// when it breaks off, and a hole that joins an older one dies there.
    Regions,
}

/// One counted hole: how long it lived (or was seen, if still open at `end`), whether it closed,
/// and its largest area (its largest member's, for a family).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CountedHole {
    pub duration: f64,
    pub closed: bool,
    pub max_area: usize,
}

/// The holes as `counting` counts them, in order of nucleation; `end` is the time of the last
/// frame (open holes are censored there).
pub fn counted_holes(holes: &[Hole], end: f64, counting: HoleCounting) -> Vec<CountedHole> {
    let one = |h: &Hole| CountedHole {
        duration: h.lifetime().unwrap_or(end - h.nucleated),
        closed: h.closed.is_some(),
        max_area: h.max_area(),
    };
    match counting {
        HoleCounting::Regions => holes.iter().map(one).collect(),
        HoleCounting::Families => {
            let root = family_roots(holes);
            // Per family, in order of its first member: root, first nucleation, last closing (∞
            // while a member is open), largest area.
            let mut families: Vec<(usize, f64, f64, usize)> = Vec::new();
            for h in holes {
                let r = root[h.id];
                let close = h.closed.unwrap_or(f64::INFINITY);
                match families.iter_mut().find(|f| f.0 == r) {
                    Some(f) => *f = (r, f.1.min(h.nucleated), f.2.max(close), f.3.max(h.max_area())),
                    None => families.push((r, h.nucleated, close, h.max_area())),
                }
            }
            families
                .into_iter()
                .map(|(_, start, close, max_area)| {
                    let closed = close.is_finite();
                    CountedHole { duration: close.min(end) - start, closed, max_area }
                })
                .collect()
        }
    }
}

/// The family of each hole ([`HoleCounting::Families`]): the id of its oldest member, by
/// union–find over the split and merge links (ids are indices into `holes`).
pub fn family_roots(holes: &[Hole]) -> Vec<usize> {
    let mut root: Vec<usize> = (0..holes.len()).collect();
    fn find(root: &mut [usize], mut a: usize) -> usize {
        while root[a] != a {
            root[a] = root[root[a]];
            a = root[a];
        }
        a
    }
    for h in holes {
        for other in [h.split_from, h.merged_into].into_iter().flatten() {
            let (a, b) = (find(&mut root, h.id), find(&mut root, other));
            // The older hole (smaller id) stands for the family.
            root[a.max(b)] = a.min(b);
        }
    }
    (0..holes.len()).map(|h| find(&mut root, h)).collect()
}

/// Distance between two points on the periodic L×L box.
pub fn periodic_distance(x0: f64, y0: f64, x1: f64, y1: f64, l: usize) -> f64 {
    let lf = l as f64;
    let d = |a: f64, b: f64| {
        let d = (a - b).rem_euclid(lf);
        d.min(lf - d)
    };
    d(x0, x1).hypot(d(y0, y1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hole(id: usize, nucleated: f64, closed: Option<f64>, area: usize) -> Hole {
        Hole { id, nucleated, closed, history: vec![(nucleated, area, 0.0, 0.0)], split_from: None, merged_into: None }
    }

    /// A hole (0) that loses a fragment (2) which closes, is joined by a pocket (1) that opens
    /// beside it, and closes; then a hole of its own (3) that is still open at the end.
    fn history() -> Vec<Hole> {
        let mut h = vec![
            hole(0, 100.0, Some(900.0), 500),
            hole(1, 150.0, Some(200.0), 60),
            hole(2, 400.0, Some(950.0), 700),
            hole(3, 1000.0, None, 80),
        ];
        h[1].merged_into = Some(0);
        h[2].split_from = Some(0);
        h
    }

    #[test]
    fn a_site_is_in_an_open_hole_only_while_its_region_holds_one() {
        // A void disk of radius 4 (above πR²/4 for R = 4) at (10, 10), and a void site alone.
        let l = 32;
        let field = |open: bool| {
            let mut p = vec![1.0; l * l];
            for y in 0..l {
                for x in 0..l {
                    if open && periodic_distance(x as f64, y as f64, 10.0, 10.0, l) <= 4.0 {
                        p[y * l + x] = 0.0;
                    }
                }
            }
            p[25 * l + 25] = 0.0;
            p
        };
        let mut t = HoleTracker::new(4.0);
        let mut v = VoidRegions::default();
        v.find(&field(true), l);
        t.update(&v, 0.0);
        assert!(t.in_open_hole(10 * l + 10) && t.in_open_hole(10 * l + 13));
        assert!(!t.in_open_hole(25 * l + 25), "a void pocket below the nucleation area is no hole");
        assert!(!t.in_open_hole(20 * l + 10));
        v.find(&field(false), l);
        t.update(&v, 1.0);
        assert!(!t.in_open_hole(10 * l + 10), "closed");
    }

    #[test]
    fn regions_count_every_tracked_region() {
        let c = counted_holes(&history(), 1200.0, HoleCounting::Regions);
        let d: Vec<(f64, bool)> = c.iter().map(|h| (h.duration, h.closed)).collect();
        assert_eq!(d, [(800.0, true), (50.0, true), (550.0, true), (200.0, false)]);
    }

    #[test]
    fn a_family_lives_from_its_first_nucleation_until_no_member_is_open() {
        let c = counted_holes(&history(), 1200.0, HoleCounting::Families);
        assert_eq!(
            c,
            [
                // 0, its joined pocket 1 and its fragment 2: from 100 until 2 closes at 950.
                CountedHole { duration: 850.0, closed: true, max_area: 700 },
                CountedHole { duration: 200.0, closed: false, max_area: 80 },
            ]
        );
        // A family with an open member is open, whatever order the links come in.
        let mut h = history();
        h[2].closed = None;
        h.swap(1, 2);
        let c = counted_holes(&h, 1200.0, HoleCounting::Families);
        assert_eq!((c[0].duration, c[0].closed), (1100.0, false));
    }
}

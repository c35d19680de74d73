//! The chaos soak's memory check, free of I/O so that it is unit-tested: a replica's RSS is
//! judged over the stretches of its life in which its load stayed the same ([`steady`]).
//!
//! Why stretches, not the run: the soak's faults move rooms. A replica that adopts a dead
//! owner's rooms holds a pipeline per room more, and its allocator keeps the pages after the
//! rooms leave again, so its RSS follows the *most* rooms it has owned in this life (its
//! high-water), not the time. Comparing the start of a run with its end would call an adopter
//! a leak (the first 5-minute runs did: r2 +12% while its rooms went from 6 to 10) and would
//! judge no replica at all once each had been killed once. A leak grows at a steady load;
//! so each stretch of one life with one high-water of rooms owned is judged on its own, after
//! it settled: the peak of its last minute against the peak of its first minute.
//!
//! The viewers load a replica too: the soak sends each back to its home replica once that is
//! up again (`clients::viewer`), so a replica's viewers are the same whenever the others are
//! up; but while another replica is down its viewers visit, and a replica that served all
//! 200 viewers at once keeps what that took (tokio's I/O slab, connection buffers and frame
//! pools sized for the peak; the allocator's pages): the 30-minute run of 2026-12-06 after the
//! frame pools' fix saw r1 step from 310 to 331 MiB while r0 and r2 were killed in turn and
//! every viewer came to it (392-512 s), then stay flat at 326-331 MiB for 460 s. So a new
//! high-water of the viewers streaming through a replica cuts a stretch too, as one of rooms
//! owned does, when it is [`VIEWER_STEP`] above the open stretch's (the reconnections'
//! overlap moves the count by a few viewers all the time).

/// A life's first seconds are not judged (connections, rooms and the allocator's arenas fill).
pub(super) const LIFE_WARM_S: f64 = 120.0;
/// After the rooms owned reach a new high-water, this long settles before the stretch is
/// judged (the new pipelines' first frames and keyframes).
pub(super) const SETTLE_S: f64 = 60.0;
/// RSS is compared as the peak over this many seconds at each end of a stretch.
pub(super) const WINDOW_S: f64 = 60.0;
/// A high-water of viewers starts a new stretch when it is this much (a fraction) above the
/// open stretch's, and at least [`VIEWER_STEP_MIN`] viewers more.
pub(super) const VIEWER_STEP: f64 = 0.1;
/// See [`VIEWER_STEP`].
pub(super) const VIEWER_STEP_MIN: usize = 5;

/// One sample of a replica's memory and load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Point {
    /// Seconds since the soak started.
    pub t: f64,
    /// Resident set, MiB.
    pub rss_mib: f64,
    /// Rooms it owned at the sample.
    pub owned: usize,
    /// The soak's viewers streaming through it at the sample.
    pub viewers: usize,
    /// Which life of the replica (its deaths before the sample).
    pub life: u32,
}

/// A stretch of one life at one high-water of rooms owned.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub(super) struct Stretch {
    /// Which life of the replica.
    pub life: u32,
    /// The most rooms it had owned in this life, through the stretch.
    pub rooms: usize,
    /// The most viewers it had served at once in this life when the stretch began.
    pub viewers: usize,
    /// Its first and last samples, seconds since the start.
    pub from: f64,
    /// See `from`.
    pub to: f64,
    /// The judged part: the peak of its first minute (after the settling) and of its last
    /// minute, MiB, and the growth from one to the other, percent. `None` when the stretch is
    /// too short to hold both minutes apart.
    pub first_peak_mib: Option<f64>,
    /// See `first_peak_mib`.
    pub last_peak_mib: Option<f64>,
    /// See `first_peak_mib`.
    pub growth_percent: Option<f64>,
}

impl Stretch {
    /// Seconds judged (0 when it is too short to judge).
    pub(super) fn judged_s(&self) -> f64 {
        match self.growth_percent {
            Some(_) => self.to - self.judged_from(),
            None => 0.0,
        }
    }

    fn judged_from(&self) -> f64 {
        self.from + SETTLE_S
    }
}

/// The highest RSS of `points` in `[from, to]`, if any lies there.
fn peak(points: &[Point], from: f64, to: f64) -> Option<f64> {
    points
        .iter()
        .filter(|p| p.t >= from && p.t <= to)
        .map(|p| p.rss_mib)
        .reduce(f64::max)
}

/// A replica's steady stretches: its samples (in time order) cut at each new life, at each
/// new high-water of the rooms it owned in that life, and at each high-water of its viewers
/// [`VIEWER_STEP`] above the open stretch's; each life's first [`LIFE_WARM_S`] left out. A
/// stretch is judged when, after [`SETTLE_S`], it holds two [`WINDOW_S`] windows apart.
pub(super) fn steady(points: &[Point]) -> Vec<Stretch> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < points.len() {
        // One life: points[i..end].
        let life = points[i].life;
        let end = points[i..]
            .iter()
            .position(|p| p.life != life)
            .map_or(points.len(), |n| i + n);
        let born = points[i].t;
        let (mut rooms, mut viewers) = (0, 0);
        // The stretch open now: its first point and its high-waters.
        let mut open: Option<(usize, usize, usize)> = None;
        for (k, p) in points.iter().enumerate().take(end).skip(i) {
            rooms = rooms.max(p.owned);
            viewers = viewers.max(p.viewers);
            if p.t < born + LIFE_WARM_S {
                continue;
            }
            match open {
                None => open = Some((k, rooms, viewers)),
                Some((s, r, v))
                    if rooms > r
                        || (viewers as f64 > v as f64 * (1.0 + VIEWER_STEP)
                            && viewers >= v + VIEWER_STEP_MIN) =>
                {
                    out.push(stretch(&points[s..k], life, r, v));
                    open = Some((k, rooms, viewers));
                }
                Some(_) => {}
            }
        }
        if let Some((s, r, v)) = open {
            out.push(stretch(&points[s..end], life, r, v));
        }
        i = end;
    }
    out
}

fn stretch(points: &[Point], life: u32, rooms: usize, viewers: usize) -> Stretch {
    let from = points.first().map_or(0.0, |p| p.t);
    let to = points.last().map_or(0.0, |p| p.t);
    let mut s = Stretch {
        life,
        rooms,
        viewers,
        from,
        to,
        first_peak_mib: None,
        last_peak_mib: None,
        growth_percent: None,
    };
    let judged = s.judged_from();
    if to - judged >= 2.0 * WINDOW_S {
        let first = peak(points, judged, judged + WINDOW_S);
        let last = peak(points, to - WINDOW_S, to);
        if let (Some(a), Some(b)) = (first, last)
            && a > 0.0
        {
            s.first_peak_mib = Some(a);
            s.last_peak_mib = Some(b);
            s.growth_percent = Some(100.0 * (b - a) / a);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check

    use super::*;

    /// Samples every 5 s from `from` to `to` (inclusive) of one life, with `owned(t)` rooms and
    /// `rss(t)` MiB.
    fn run(
        from: f64,
        to: f64,
        life: u32,
        owned: impl Fn(f64) -> usize,
        rss: impl Fn(f64) -> f64,
    ) -> Vec<Point> {
        let mut out = Vec::new();
        let mut t = from;
        while t <= to + 1e-9 {
            out.push(Point {
                t,
                rss_mib: rss(t),
                owned: owned(t),
                viewers: 60,
                life,
            });
            t += 5.0;
        }
        out
    }

    #[test]
    fn an_adopter_that_grows_with_its_rooms_is_not_a_leak() {
        // 6 rooms until 600 s, 10 after; each room adds 7 MiB, reached 30 s after adoption
        // (inside the settling); flat otherwise. The whole run's start-to-end growth is 12%.
        let points = run(
            0.0,
            1200.0,
            0,
            |t| if t < 600.0 { 6 } else { 10 },
            |t| {
                let rooms = if t < 630.0 { 6.0 } else { 10.0 };
                200.0 + 7.0 * rooms
            },
        );
        let s = steady(&points);
        assert_eq!(s.len(), 2, "{s:?}");
        assert_eq!((s[0].rooms, s[1].rooms), (6, 10));
        assert_eq!((s[0].from, s[1].from), (120.0, 600.0));
        for x in &s {
            assert_eq!(x.growth_percent, Some(0.0), "{x:?}");
        }
        assert!((s[1].judged_s() - (1200.0 - 660.0)).abs() < 1e-9);
    }

    #[test]
    fn a_leak_at_a_steady_load_is_found() {
        // 8 rooms throughout; 20 MiB an hour on 250.
        let points = run(0.0, 1800.0, 0, |_| 8, |t| 250.0 + 20.0 * t / 3600.0);
        let s = steady(&points);
        assert_eq!(s.len(), 1);
        // First window (180, 240] peaks at 240 s, the last (1740, 1800] at 1800 s.
        let a = 250.0 + 20.0 * 240.0 / 3600.0;
        let b = 250.0 + 20.0 * 1800.0 / 3600.0;
        let g = s[0].growth_percent.unwrap();
        assert!((g - 100.0 * (b - a) / a).abs() < 1e-9, "{g}");
        assert!(g > 3.0);
    }

    #[test]
    fn fewer_rooms_do_not_cut_a_stretch_and_a_new_life_starts_one() {
        // Life 0: 5 rooms, then 3 (the allocator keeps the pages: no new stretch), killed at
        // 700 s; life 1 from 720 s with 0 rooms, then 4 from 1000 s.
        let mut points = run(0.0, 700.0, 0, |t| if t < 400.0 { 5 } else { 3 }, |_| 240.0);
        points.extend(run(
            720.0,
            1500.0,
            1,
            |t| if t < 1000.0 { 0 } else { 4 },
            |t| {
                if t < 1000.0 { 150.0 } else { 180.0 }
            },
        ));
        let s = steady(&points);
        let shape: Vec<(u32, usize, f64, f64)> =
            s.iter().map(|x| (x.life, x.rooms, x.from, x.to)).collect();
        assert_eq!(
            shape,
            vec![
                (0, 5, 120.0, 700.0),
                (1, 0, 840.0, 995.0),
                (1, 4, 1000.0, 1500.0)
            ]
        );
        // Life 1's first stretch: 155 s, too short to hold settling and two windows apart.
        assert_eq!(s[1].growth_percent, None);
        assert_eq!(s[1].judged_s(), 0.0);
        assert_eq!(s[0].growth_percent, Some(0.0));
        assert_eq!(s[2].growth_percent, Some(0.0));
    }

    #[test]
    fn a_high_water_reached_in_the_warm_up_counts() {
        // 9 rooms for a moment in the warm-up, 4 after: the stretch after the warm-up is at
        // the high-water 9, and a later 7 is not a new one.
        let points = run(
            0.0,
            900.0,
            0,
            |t| {
                if t < 60.0 {
                    9
                } else if t < 500.0 {
                    4
                } else {
                    7
                }
            },
            |_| 220.0,
        );
        let s = steady(&points);
        assert_eq!(s.len(), 1, "{s:?}");
        assert_eq!(s[0].rooms, 9);
    }

    #[test]
    fn a_burst_of_visiting_viewers_cuts_a_stretch_and_a_few_do_not() {
        // 20 rooms throughout; 60 viewers, 62-64 now and then (reconnections overlapping),
        // and 200 from 400 s to 520 s (the other replicas down): RSS steps from 310 to 330 MiB
        // during the burst and stays there (what the burst took is kept, not leaked).
        let mut points = run(
            0.0,
            1100.0,
            0,
            |_| 20,
            |t| if t < 420.0 { 310.0 } else { 330.0 },
        );
        for p in &mut points {
            p.viewers = if (400.0..520.0).contains(&p.t) {
                200
            } else if (p.t as u64 / 5).is_multiple_of(7) {
                64
            } else {
                60
            };
        }
        let s = steady(&points);
        let shape: Vec<(usize, f64)> = s.iter().map(|x| (x.viewers, x.from)).collect();
        assert_eq!(shape, vec![(64, 120.0), (200, 400.0)], "{s:?}");
        assert_eq!(s[0].growth_percent, Some(0.0));
        assert_eq!(s[1].growth_percent, Some(0.0));
        // Without the burst, the same step is a leak at a steady load.
        for p in &mut points {
            p.viewers = 60;
        }
        let s = steady(&points);
        assert_eq!(s.len(), 1);
        assert!(s[0].growth_percent.unwrap() > 5.0, "{s:?}");
    }
}

//! Board time against host time: round trips of [`crate::msg::Request::Ping`] and the line
//! that maps the board's µs clock onto the host's. No I/O here: the client takes the pings,
//! this fits them.
//!
//! Each ping is bracketed by the host's clock: sent at `host_sent_us`, answered at
//! `host_received_us`; the board read its clock somewhere in between, so the board time maps to
//! the midpoint with an error of at most half the round trip. [`Alignment::offset`] takes the
//! quickest round trip of a burst and assumes equal rates; [`Alignment::fit`] takes the quickest
//! of the first third of the pings and of the last third (so the two are at least a third of the
//! span apart): the offset from one, the drift (the board crystal's rate error) from the two.

/// One round trip.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ping {
    /// Host clock when the request left, µs.
    pub host_sent_us: u64,
    /// Host clock when the reply was read, µs.
    pub host_received_us: u64,
    /// The board's clock in the reply, µs since boot.
    pub board_us: u64,
}

impl Ping {
    /// The round trip, µs.
    pub fn round_trip_us(&self) -> u64 {
        self.host_received_us.saturating_sub(self.host_sent_us)
    }

    /// The host time the board's reading maps to (the round trip's midpoint), µs.
    pub fn host_mid_us(&self) -> f64 {
        (self.host_sent_us as f64 + self.host_received_us as f64) / 2.0
    }
}

/// Board time mapped onto host time: `host_us = host_ref_us + (board_us − board_ref_us) · rate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// Board time of the reference ping, µs since boot.
    pub board_ref_us: u64,
    /// Host time of the reference ping (its midpoint), µs.
    pub host_ref_us: f64,
    /// Host µs per board µs (1 + drift).
    pub rate: f64,
    /// Worst error of a mapped time between the two pings fitted: half the slower of their
    /// round trips, µs. Outside that span the drift's own error adds to it.
    pub error_us: f64,
    /// The span between the pings fitted, board µs (0: one ping, no drift measured).
    pub span_us: u64,
}

impl Alignment {
    /// The quickest round trip of `pings`, the two clocks taken to run at the same rate: for
    /// a burst of pings taken back to back, too close together to measure a drift.
    pub fn offset(pings: &[Ping]) -> Option<Self> {
        let p = pings.iter().copied().min_by_key(Ping::round_trip_us)?;
        Some(Self::between(p, p))
    }

    /// Fits `pings` (in the order taken): the quickest of the first third and of the last
    /// third; `None` without any.
    pub fn fit(pings: &[Ping]) -> Option<Self> {
        let quickest = |ps: &[Ping]| ps.iter().copied().min_by_key(Ping::round_trip_us);
        let third = pings.len().div_ceil(3);
        if pings.len() < 2 {
            return Self::offset(pings);
        }
        let a = quickest(&pings[..third])?;
        let b = quickest(&pings[pings.len() - third..])?;
        Some(Self::between(a, b))
    }

    fn between(a: Ping, b: Ping) -> Self {
        let span_us = b.board_us.saturating_sub(a.board_us);
        let rate = if span_us == 0 {
            1.0
        } else {
            (b.host_mid_us() - a.host_mid_us()) / span_us as f64
        };
        Alignment {
            board_ref_us: a.board_us,
            host_ref_us: a.host_mid_us(),
            rate,
            error_us: a.round_trip_us().max(b.round_trip_us()) as f64 / 2.0,
            span_us,
        }
    }

    /// The host time of board time `board_us`, µs.
    pub fn host_us(&self, board_us: u64) -> f64 {
        self.host_ref_us + (board_us as f64 - self.board_ref_us as f64) * self.rate
    }

    /// The board clock's rate error against the host's, parts per million (positive: the
    /// board's clock runs fast, more board µs pass than host µs); 0 when not measured.
    pub fn drift_ppm(&self) -> f64 {
        (1.0 / self.rate - 1.0) * 1e6
    }

    /// How far [`Self::drift_ppm`] may be off: both ends' error over the span, ppm (infinite
    /// when no span was measured).
    pub fn drift_error_ppm(&self) -> f64 {
        if self.span_us == 0 {
            return f64::INFINITY;
        }
        2.0 * self.error_us / self.span_us as f64 * 1e6
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pings of a board whose clock is `board = (host − 5 s) / 1.0002`, each read `at` µs
    /// after the request left and answered `rtt` µs after it left.
    fn ping(host_sent_us: u64, at: u64, rtt: u64) -> Ping {
        let host_read = (host_sent_us + at) as f64;
        Ping {
            host_sent_us,
            host_received_us: host_sent_us + rtt,
            board_us: ((host_read - 5e6) / 1.0002).round() as u64,
        }
    }

    #[test]
    fn the_quickest_round_trips_give_offset_and_drift_within_half_a_round_trip() {
        // Slow pings with the board's reading off-centre, quick ones centred.
        let pings = [
            ping(10_000_000, 900, 1_000),
            ping(10_100_000, 100, 200),
            ping(10_200_000, 50, 3_000),
            ping(70_000_000, 2_900, 3_000),
            ping(70_100_000, 150, 300),
            ping(70_200_000, 10, 400),
        ];
        let a = Alignment::fit(&pings).unwrap();
        assert_eq!(
            a.error_us, 150.0,
            "half the slower of the two quick round trips"
        );
        // The quickest of each third: the second ping and the fifth.
        assert_eq!(a.board_ref_us, pings[1].board_us);
        assert_eq!(a.span_us, pings[4].board_us - pings[1].board_us);
        // The board's clock runs slow: 1/1.0002 − 1 = −199.96 ppm, to within what 2 × 150 µs
        // over 60 s allows (5 ppm), which is what it says.
        assert_eq!(a.drift_error_ppm(), 2.0 * 150.0 / a.span_us as f64 * 1e6);
        let want = (1.0 / 1.0002 - 1.0) * 1e6;
        assert!(
            (a.drift_ppm() - want).abs() < a.drift_error_ppm(),
            "{}",
            a.drift_ppm()
        );
        // Any board time between the pings maps to its true host time within the bound.
        for host in [10_100_100u64, 30_000_000, 50_000_000, 70_100_150] {
            let board = ((host as f64 - 5e6) / 1.0002).round() as u64;
            let err = (a.host_us(board) - host as f64).abs();
            assert!(err <= a.error_us + 1.0, "at host {host}: {err} µs");
        }
    }

    #[test]
    fn the_quickest_pings_are_a_third_of_the_span_apart() {
        // The two quickest round trips sit side by side in the middle: a fit of the halves'
        // quickest would measure the drift over 1 s of a 9 s span.
        let mut pings: Vec<Ping> = (0..9)
            .map(|i| ping(10_000_000 + i * 1_000_000, 500, 1_000))
            .collect();
        pings[4] = ping(14_000_000, 50, 100);
        pings[5] = ping(15_000_000, 50, 100);
        let a = Alignment::fit(&pings).unwrap();
        assert!(a.span_us > 5_000_000, "{}", a.span_us);
        // A burst taken back to back: the offset only.
        let o = Alignment::offset(&pings[3..6]).unwrap();
        assert_eq!(
            (o.rate, o.span_us, o.board_ref_us),
            (1.0, 0, pings[4].board_us)
        );
        assert_eq!(o.drift_error_ppm(), f64::INFINITY);
    }

    #[test]
    fn one_ping_gives_an_offset_and_no_drift() {
        let a = Alignment::fit(&[ping(1_000_000, 100, 200)]).unwrap();
        assert_eq!((a.rate, a.span_us, a.error_us), (1.0, 0, 100.0));
        assert_eq!(a.host_ref_us, 1_000_100.0);
        assert!(Alignment::fit(&[]).is_none());
    }
}

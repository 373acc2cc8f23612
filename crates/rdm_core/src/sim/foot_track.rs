//! The foot plate's contact anchor: where and how the plate lay when a contact began, and
//! when it last touched an environment surface. The anchor survives contact gaps up to the
//! release time (a sliding or vibrating foot chatters on and off the surface); after a
//! longer gap the next contact starts a new anchor. One form: `_rdm.FootTrackerCore`
//! holds it for `rdm.plant.truth.FootContactTracker` and the lockstep kernel.

/// The plate's pose at first contact: world position and row-major rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    pub pos: [f64; 3],
    pub rot: [f64; 9],
}

/// The contact anchor and the last contact time (see the module doc). Allocates nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct FootTrack {
    /// Longest contact gap [s] the anchor survives.
    pub release_time: f64,
    last_contact_time: f64,
    anchor: Option<Anchor>,
}

impl FootTrack {
    /// No anchor, no contact yet.
    pub fn new(release_time: f64) -> Self {
        FootTrack {
            release_time,
            last_contact_time: f64::NEG_INFINITY,
            anchor: None,
        }
    }

    /// The last time the plate touched (-inf: never since the last release).
    pub fn last_contact_time(&self) -> f64 {
        self.last_contact_time
    }

    /// The first-contact anchor, when set.
    pub fn anchor(&self) -> Option<&Anchor> {
        self.anchor.as_ref()
    }

    /// No anchor and no contact time to release: tracking a step without a plate contact
    /// changes nothing.
    pub fn idle(&self) -> bool {
        self.anchor.is_none() && self.last_contact_time == f64::NEG_INFINITY
    }

    /// One step at `time` with (`in_contact`) or without a plate contact: a contact stamps
    /// the time; a gap longer than the release time forgets the anchor. True: a contact
    /// without an anchor (the caller sets it with [`FootTrack::set_anchor`]).
    pub fn track(&mut self, time: f64, in_contact: bool) -> bool {
        if in_contact {
            self.last_contact_time = time;
            return self.anchor.is_none();
        }
        if time - self.last_contact_time > self.release_time {
            self.reset();
        }
        false
    }

    /// The plate's pose at this contact's start.
    pub fn set_anchor(&mut self, pos: [f64; 3], rot: [f64; 9]) {
        self.anchor = Some(Anchor { pos, rot });
    }

    /// Forget the anchor and the contact time.
    pub fn reset(&mut self) {
        self.last_contact_time = f64::NEG_INFINITY;
        self.anchor = None;
    }
}

/// Whether any geom of `geoms` (a contact list's geom pairs) is one of `plate_geoms`.
pub fn plate_in(geoms: impl IntoIterator<Item = i32>, plate_geoms: &[i32]) -> bool {
    geoms.into_iter().any(|g| plate_geoms.contains(&g))
}

#[cfg(test)]
mod tests {
    use super::*;

    const POS: [f64; 3] = [0.1, 0.2, 1.9];
    const ROT: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

    #[test]
    fn the_first_contact_asks_for_an_anchor_and_later_ones_only_stamp() {
        let mut t = FootTrack::new(0.1);
        assert!(t.idle());
        assert!(!t.track(0.5, false), "no contact: nothing to anchor");
        assert!(t.idle(), "-inf + a gap releases nothing that is set");
        assert!(t.track(1.0, true));
        t.set_anchor(POS, ROT);
        assert!(!t.track(1.001, true));
        assert_eq!(t.last_contact_time(), 1.001);
        assert_eq!(t.anchor().map(|a| a.pos), Some(POS));
    }

    #[test]
    fn the_anchor_survives_a_gap_up_to_the_release_time_only() {
        let mut t = FootTrack::new(0.125);
        t.track(1.0, true);
        t.set_anchor(POS, ROT);
        t.track(1.125, false); // exactly the release time: kept (strictly longer releases)
        assert!(t.anchor().is_some());
        t.track(1.126, false);
        assert!(t.anchor().is_none() && t.idle());
        assert!(t.track(2.0, true), "the next contact starts a new anchor");
    }

    #[test]
    fn plate_in_finds_a_plate_geom_on_either_side_of_a_pair() {
        assert!(plate_in([3, 7, 9, 2], &[2, 5]));
        assert!(plate_in([5, 0], &[2, 5]));
        assert!(!plate_in([3, 7, 9, 1], &[2, 5]));
        assert!(!plate_in([], &[2]));
    }
}

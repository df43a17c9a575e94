//! Motion threshold: the speed gate of the textures rendered from velocity (a velocity-synthesis
//! grating, a material), so that the estimate's noise at rest makes no bursts.

use crate::burst::FastPlanner;

use super::compiled::Request;

/// Speed threshold with hysteresis: on at `on_um_s`, off below half of it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MotionGate {
    on_um_s: f32,
    moving: bool,
}

impl MotionGate {
    pub(crate) fn new(min_speed_um_s: u32) -> Self {
        Self {
            on_um_s: min_speed_um_s as f32,
            moving: false,
        }
    }

    /// Back to "at rest" (region change, fault): motion must be seen again above the threshold.
    pub(crate) fn reset(&mut self) {
        self.moving = false;
    }

    /// The speed to render, or None while below the threshold (or velocity unknown).
    pub(crate) fn speed(&mut self, velocity_um_s: Option<i32>) -> Option<f32> {
        let Some(v) = velocity_um_s else {
            self.moving = false;
            return None;
        };
        let speed = (v as f32).abs();
        self.moving = if self.moving {
            speed >= 0.5 * self.on_um_s
        } else {
            speed >= self.on_um_s
        };
        self.moving.then_some(speed)
    }

    /// Periodic bursts at `hz_at(speed)` (speed in µm/s) while moving, at `amplitude` ‰; off
    /// below the threshold.
    #[inline]
    pub(crate) fn request(
        &mut self,
        velocity_um_s: Option<i32>,
        planner: &FastPlanner,
        amplitude: u16,
        hz_at: impl FnOnce(f32) -> f32,
    ) -> Request {
        match self.speed(velocity_um_s) {
            Some(speed) => Request::planned(planner.plan_hz(hz_at(speed)), amplitude),
            None => Request::OFF,
        }
    }
}

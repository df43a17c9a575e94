//! The host link's bytes as a board with the 4-wire touch overlay takes them (issue #36): the
//! line through the frame receiver, or one frame's header and body, into a 2D board's session
//! over a real `Controller2d` (`bodies/plane.rs`, `link_bytes_2d`: replies encode, refusals
//! change nothing, the session never hands the overlay a 1D scene).
#![no_main]

#[path = "../bodies/plane.rs"]
mod plane;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = plane::link_bytes_2d(data);
});

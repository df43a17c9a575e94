use rand::Rng;
use host_sim::soak::{episode, gen};
use host_sim::sim::{burst_timer, sample_period_us};
#[test]
fn scratch() {
    let mut rng = episode::episode_rng(1, 24581);
    let board = &saw_boards::ALL[rng.random_range(0..saw_boards::ALL.len())];
    let timer = burst_timer(board);
    let period_us = sample_period_us(board);
    for _ in 0..16 {
        let cfg = gen::random_config(&mut rng, timer.max_burst_hz);
        if saw_core::controller::Prepared::compile(&timer, period_us, &cfg).is_ok() {
            eprintln!("board {} limits {:?}", board.name, cfg.limits);
            for t in &cfg.scene.textures { eprintln!("  {t:?}"); }
            eprintln!("  lines {:?} bounds {:?}", cfg.scene.lines, cfg.scene.boundaries_um);
            break;
        }
    }
}

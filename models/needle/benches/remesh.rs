//! Tip remeshing per frame (issue 18: "remeshing under 1 ms per frame" at
//! the seed's prostate size): `Channel::tip_to` on a Kuhn block of 13,824
//! tets / 2,873 nodes (the seed's prostate mesh has 13,375 tets / ~2,760
//! vertices), the tip moving 0.1 mm a frame along a straight off-grid
//! path, in to 20 mm and back out, over and over (remeshing only: no
//! physics). Shaft nodes every cell (2.5 mm).
//!
//! Measured (criterion, 2-core Intel Xeon, load average ~1 from this
//! session's shell, 1 thread: the remesher is sequential): 88 us per frame
//! (86-91 us), against the seed's 0.5-0.9 ms remeshing column (Chentanez
//! et al. 2009, Table 2).

use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Duration;
use surgbench_core::{Vec3, mesh};
use surgbench_needle::remesh::Channel;

fn bench(c: &mut Criterion) {
    let cells = [16, 12, 12];
    let h = 2.5e-3;
    let block = mesh::block(Vec3::new(16.0 * h, 12.0 * h, 12.0 * h), cells);
    assert_eq!(block.tets.len(), 13_824);
    let (y0, z0) = (6.13 * h, 5.87 * h);
    let path = move |a: f64| Vec3::new(a, y0, z0);
    let da = 1e-4;
    let n = 200; // 20 mm in
    let frames: Vec<f64> = (0..=n).chain((0..n).rev()).map(|k| k as f64 * da).collect();
    let mut g = c.benchmark_group("needle_remesh_13824_tets");
    g.sample_size(30)
        .measurement_time(Duration::from_secs(4))
        .warm_up_time(Duration::from_secs(1));
    let mut ch = Channel::new(&block, h);
    let mut k = 0;
    g.bench_function("tip_to_0.1mm", |b| {
        b.iter(|| {
            ch.tip_to(frames[k % frames.len()], path).expect("remesh");
            k += 1;
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

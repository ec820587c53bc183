//! Encode/decode throughput of a 256 x 256 terrain map (the largest message the stack sends).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lcm_types::pfnav::{Header, TerrainMap};
use lcm_types::Message;

fn map_256() -> TerrainMap {
    let side = 256usize;
    let cells = side * side;
    let heights: Vec<f64> = (0..cells)
        .map(|i| {
            let (x, y) = ((i % side) as f64, (i / side) as f64);
            (0.05 * x).sin() * (0.03 * y).cos()
        })
        .collect();
    TerrainMap {
        header: Header {
            utime: 1_700_000_000_000_000,
            seq: 42,
            frame_id: "world".to_string(),
        },
        origin_x: -12.8,
        origin_y: -12.8,
        resolution: 0.1,
        width: side as i32,
        height: side as i32,
        num_cells: cells as i32,
        heights,
        num_obstacle_cells: cells as i32,
        obstacle_mask: (0..cells).map(|i| i % 17 == 0).collect(),
        // Every cell known: the map as a finished survey sends it.
        ..TerrainMap::default()
    }
}

fn bench_codec(c: &mut Criterion) {
    let map = map_256();
    let bytes = map.encode().expect("the benchmark map is consistent");
    let mut group = c.benchmark_group("terrain_map_256x256");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.bench_function("encode", |b| {
        b.iter(|| std::hint::black_box(&map).encode().expect("encodes"))
    });
    group.bench_function("decode", |b| {
        b.iter(|| TerrainMap::decode(std::hint::black_box(&bytes)).expect("decodes"))
    });
    group.finish();
}

criterion_group!(benches, bench_codec);
criterion_main!(benches);

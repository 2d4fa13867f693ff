//! Tests of the couplings: analytic form factors of squares, the per-bin cap, coplanar pairs.

use super::*;

fn square(z: f64, up: bool) -> [Tri; 2] {
    let (a, b, c, d) = (
        DVec3::new(0.0, 0.0, z),
        DVec3::new(1.0, 0.0, z),
        DVec3::new(1.0, 1.0, z),
        DVec3::new(0.0, 1.0, z),
    );
    if up {
        [[a, b, c], [a, c, d]]
    } else {
        [[a, c, b], [a, d, c]]
    }
}

fn geom(t: Tri) -> PatchGeom {
    PatchGeom::new(t, geometry::normal(&t).unwrap())
}

/// Form factor from receiver square to sender square via couplings, area weighted.
fn square_ff(recv: [Tri; 2], send: [Tri; 2], bins: &Bins) -> f64 {
    let params = CouplingParams::default();
    let mut out = Coupling::new();
    let mut total = 0.0;
    let send_geoms: Vec<PatchGeom> = send.iter().map(|s| geom(*s)).collect();
    for r in &recv {
        let receiver = Receiver::for_senders(geom(*r), &send_geoms, &params);
        for s in &send_geoms {
            couple(&receiver, s, bins, &params, &mut out);
            let f: f64 = out.iter().map(|e| e.f_b as f64).sum();
            assert!(
                out.iter().all(|e| e.f_a == 0.0),
                "front-facing: no antiradiance read"
            );
            total += f * geometry::area(r);
        }
    }
    total
}

#[test]
fn parallel_squares() {
    let bins = Bins::new(8);
    let f = square_ff(square(0.0, true), square(1.0, false), &bins);
    eprintln!("par {f}");
    assert!((f - 0.19982).abs() < 0.01 * 0.19982, "{f}");
}

#[test]
fn perpendicular_squares() {
    let bins = Bins::new(8);
    let floor = square(0.0, true);
    // Wall in the plane y = 0, facing +y, sharing the edge y = 0, z = 0.
    let (a, b, c, d) = (
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::new(1.0, 0.0, 1.0),
        DVec3::new(1.0, 0.0, 0.0),
    );
    let wall = [[a, b, c], [a, c, d]];
    assert!(geometry::normal(&wall[0]).unwrap().y > 0.9);
    let f = square_ff(floor, wall, &bins);
    eprintln!("perp {f}");
    assert!((f - 0.20004).abs() < 0.01 * 0.20004, "{f}");
}

#[test]
fn no_bin_gets_more_than_its_solid_angle() {
    let bins = Bins::new(4);
    let params = CouplingParams::default();
    let mut out = Coupling::new();
    // A huge sender right above a small receiver covers many bins.
    let big = [
        DVec3::new(-50.0, -50.0, 0.01),
        DVec3::new(-50.0, 100.0, 0.01),
        DVec3::new(100.0, -50.0, 0.01),
    ];
    let s = geom(big);
    let r = Receiver::for_senders(geom(square(0.0, true)[0]), [&s], &params);
    couple(&r, &s, &bins, &params, &mut out);
    assert!(out.len() > 4, "spread over bins: {}", out.len());
    for e in &out {
        assert!(e.o_a <= 1.0 + 1e-6, "{e:?}");
    }
    let total: f64 = out.iter().map(|e| e.f_b as f64).sum();
    assert!(total > 0.9 && total <= 1.0 + 1e-6, "{total}");
}

#[test]
fn coplanar_pairs_exchange_nothing() {
    let bins = Bins::new(8);
    let sq = square(0.0, true);
    let mut out = Coupling::new();
    couple(
        &Receiver::new(geom(sq[0]), 6),
        &geom(sq[1]),
        &bins,
        &CouplingParams::default(),
        &mut out,
    );
    assert!(out.is_empty());
}

mod group_tests {
    use super::super::*;
    use crate::mesh::build_patches;
    use crate::scene::generated;
    use crate::scene::Scene;

    /// A 1 x 1 emitter (facing down, split into 16 x 16 x 2 triangles so it forms one group
    /// whose member tree has several levels)
    /// over receivers in every relation to it: below, tilted, cutting its plane, beside it in its
    /// plane, above it (behind), touching its edge, and below it with their planes cutting it
    /// (between its triangles' corners, one of them close).
    fn grouped_scene() -> Scene {
        let v = DVec3::new;
        let light = [
            [v(0.0, 1.0, 0.0), v(1.0, 1.0, 0.0), v(1.0, 1.0, 1.0)],
            [v(0.0, 1.0, 0.0), v(1.0, 1.0, 1.0), v(0.0, 1.0, 1.0)],
        ];
        let mut corners: Vec<[DVec3; 3]> = Vec::new();
        let light_scene = generated::subdivide(
            &Scene::from_triangles(&light, &[[0.0; 3]; 2], &[[1.0; 3]; 2]),
            16,
        );
        for t in 0..light_scene.len() {
            corners.push(light_scene.corners(t));
        }
        let emitters = corners.len();
        let receivers = [
            [v(0.2, 0.0, 0.2), v(0.8, 0.0, 0.8), v(0.8, 0.0, 0.2)], // below, facing up
            [v(-0.5, 0.2, 0.0), v(-0.5, 0.8, 1.0), v(-0.2, 0.0, 1.0)], // tilted, aside
            [v(0.5, 0.5, 0.0), v(0.5, 1.5, 0.0), v(0.5, 0.5, 1.0)], // cuts the light's plane
            [v(1.5, 1.0, 0.0), v(2.0, 1.0, 0.5), v(1.5, 1.0, 1.0)], // in its plane
            [v(0.2, 1.5, 0.2), v(0.2, 1.5, 0.8), v(0.8, 1.5, 0.2)], // above (behind it)
            [v(1.0, 1.0, 0.0), v(1.0, 0.0, 0.0), v(1.0, 1.0, 1.0)], // wall on its edge
            [v(0.3, 0.0, 0.1), v(0.3, 0.9, 0.1), v(0.3, 0.0, 0.9)], // below, its plane cuts it
            [v(0.62, 0.95, 0.0), v(0.62, 0.0, 1.0), v(0.62, 0.95, 1.0)], // near, cuts it
        ];
        corners.extend(receivers);
        let n = corners.len();
        let mut emission = vec![[0.0; 3]; n];
        emission[..emitters].fill([1.0; 3]);
        Scene::from_triangles(&corners, &vec![[0.5; 3]; n], &emission)
    }

    /// Asserts that every patch of `scene` sees each emitter group as the sum of its members.
    fn assert_group_is_its_members_sum(scene: &Scene) -> DirectLight<'static> {
        let patches: &'static _ = Box::leak(Box::new(build_patches(scene, None)));
        let light = DirectLight::new(patches, patches.len());
        assert!(light.group_count() >= 1);
        for p in 0..patches.len() {
            let r = Element {
                corners: patches.corners[p],
                normal: patches.normal[p],
                area: patches.area[p],
                patch: p as u32,
            };
            let receiver = PatchGeom::new(r.corners, r.normal);
            let grouped = light.unoccluded(&r, &mut Vec::new(), &mut Vec::new())[0];
            let member_sum: f64 = (0..light.emitters.len())
                .map(|k| light.emitter_form_factor(&r, &receiver, k))
                .sum();
            assert!(
                (grouped - member_sum).abs() <= 1e-12 + 1e-9 * member_sum,
                "patch {p}: grouped {grouped} vs members {member_sum}"
            );
        }
        light
    }

    #[test]
    fn groups_give_the_sum_of_their_members() {
        let light = assert_group_is_its_members_sum(&grouped_scene());
        assert_eq!(light.group_count(), 1, "the split light is one group");
        assert_eq!(
            light.groups[0].boundary.len(),
            4,
            "the square's rim of 4 x 16 edges, merged into its 4 sides"
        );
    }

    /// The subdivided Cornell box: its light of 2 x 8 x 8 triangles seen from the walls and the
    /// boxes, whose sides' planes cut it.
    #[test]
    fn the_subdivided_cornell_box_light_is_the_sum_of_its_members() {
        let light = assert_group_is_its_members_sum(&generated::subdivided_cornell_box(3000));
        assert!(light.groups.iter().all(|g| g.planar && g.manifold));
    }

    /// A square ring light (3 x 3 with a 1 x 1 hole, facing down, 256 triangles) over receivers
    /// whose planes cut it through the hole, beside it and across a corner: the cut crosses the
    /// rim four times, or twice. (The unit frame's rounding may split the ring into groups; a
    /// U-shaped one is crossed four times too.)
    #[test]
    fn a_ring_light_cut_through_its_hole_gives_the_sum_of_its_members() {
        let v = DVec3::new;
        let mut corners: Vec<[DVec3; 3]> = Vec::new();
        let at = |i: usize, j: usize| v(i as f64 / 4.0, 1.0, j as f64 / 4.0);
        for i in 0..12 {
            for j in 0..12 {
                if (4..8).contains(&i) && (4..8).contains(&j) {
                    continue;
                }
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                corners.extend([[a, b, c], [a, c, d]]);
            }
        }
        let emitters = corners.len();
        corners.extend([
            [v(1.5, 0.0, -1.0), v(1.5, 0.9, 4.0), v(1.5, 0.0, 4.0)], // through the hole
            [v(1.5, 0.0, -1.0), v(1.5, 0.0, 4.0), v(1.5, 0.9, 4.0)], // the same, facing back
            [v(1.2, 0.0, -1.0), v(1.8, 0.0, 4.0), v(1.5, 0.95, 1.5)], // tilted, through it
            [v(0.5, 0.0, -1.0), v(0.5, 0.8, 4.0), v(0.5, 0.0, 4.0)], // beside the hole
            [v(2.5, 0.0, 0.0), v(3.2, 0.0, 1.0), v(3.0, 0.9, 0.0)],  // across a corner
            [v(0.0, 0.0, 0.0), v(3.0, 0.0, 3.0), v(3.0, 0.0, 0.0)],  // below, facing up
        ]);
        let n = corners.len();
        let mut emission = vec![[0.0; 3]; n];
        emission[..emitters].fill([1.0; 3]);
        let scene = Scene::from_triangles(&corners, &vec![[0.5; 3]; n], &emission);
        let light = assert_group_is_its_members_sum(&scene);
        assert!(light.groups.iter().all(|g| g.planar && g.manifold));
        assert!(
            light.groups.iter().any(|g| g.boundary.len() >= 8),
            "a group that is not convex"
        );
    }
}

mod sampling_tests {
    use super::super::*;
    use crate::mesh::build_patches;
    use crate::scene::Scene;

    /// Reflected direct light of patch 0 (a unit receiver facing up at y = 0) in a scene of
    /// `corners` with `emission`, albedo 0.5 everywhere.
    fn direct_on_receiver(corners: &[[DVec3; 3]], emission: &[[f64; 3]]) -> f64 {
        let scene = Scene::from_triangles(corners, &vec![[0.5; 3]; corners.len()], emission);
        let patches = build_patches(&scene, None);
        let receivers = patch_receivers(&patches);
        let light = DirectLight::new(&patches, receivers.len());
        let (reflected, _) = light.reflected(&receivers, &Progress::hidden());
        let at = receivers.iter().position(|r| r.patch == 0).unwrap();
        reflected[at][0]
    }

    /// A small light just above a receiver, and a light ten million times as powerful hidden
    /// from it behind a plate: the hidden light must not change the receiver's direct light.
    /// (Shadow rays chosen by the emitters' power all went to the hidden light, found it
    /// blocked, and left the receiver dark: the bear lit by its own head was 11% off.)
    #[test]
    fn a_hidden_powerful_light_does_not_darken_a_receiver_lit_by_a_small_one() {
        let v = DVec3::new;
        let receiver = [v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(1.0, 0.0, 0.0)];
        let small = [v(0.3, 0.3, 0.3), v(0.4, 0.3, 0.3), v(0.3, 0.3, 0.4)];
        let square = |y: f64, half: f64, down: bool| {
            let (a, b, c, d) = (
                v(-half, y, -half),
                v(half, y, -half),
                v(half, y, half),
                v(-half, y, half),
            );
            if down {
                [[a, b, c], [a, c, d]]
            } else {
                [[a, c, b], [a, d, c]]
            }
        };
        let alone = direct_on_receiver(&[receiver, small], &[[0.0; 3], [1.0; 3]]);
        let [h0, h1] = square(20.0, 50.0, true);
        let [p0, p1] = square(10.0, 100.0, true);
        let hidden = direct_on_receiver(
            &[receiver, small, h0, h1, p0, p1],
            &[[0.0; 3], [1.0; 3], [1.0; 3], [1.0; 3], [0.0; 3], [0.0; 3]],
        );
        assert!(alone > 0.0);
        assert!(
            (hidden - alone).abs() <= 0.05 * alone,
            "with a hidden light {hidden}, without {alone}"
        );
    }
}

mod budget_tests {
    use super::super::*;
    use crate::mesh::build_patches;
    use crate::scene::generated;

    /// The sampled groups per receiver bound what the receivers keep: with every third patch of
    /// the 4k-triangle Cornell box emitting (many groups, each receiver lit by those in front
    /// of it), the estimate is at least the mean kept and at most every group.
    #[test]
    fn sampled_lights_per_receiver_bound_what_receivers_keep() {
        let mut scene = generated::subdivided_cornell_box(4_000);
        for t in (0..scene.len()).step_by(3) {
            scene.emission[t] = [1.0; 3];
        }
        let patches = build_patches(&scene, None);
        let receivers = super::super::solvers::patch_receivers(&patches);
        let direct = DirectLight::new(&patches, receivers.len());
        let groups = direct.group_count() as u64;
        let (mut lights, mut parts) = (Vec::new(), Vec::new());
        let kept: usize = receivers
            .iter()
            .map(|r| {
                direct.unoccluded(r, &mut lights, &mut parts);
                lights.len()
            })
            .sum();
        let mean = kept.div_ceil(receivers.len()) as u64;
        let estimate = direct.lights_per_receiver(&receivers);
        assert!(estimate >= mean, "estimate {estimate}, mean {mean}");
        assert!(
            groups > 8 && estimate <= groups,
            "estimate {estimate}, groups {groups}"
        );
    }

    /// Where every group at every receiver fits [`LIGHTS_UNSAMPLED_BYTES`], every group is
    /// counted, not a sample's estimate: in the 1k-triangle Cornell box with every third patch
    /// emitting and turned over, receivers keep few groups, and the sampled estimate would be
    /// well under every group. (The 4k-triangle box is sampled: the test above.)
    #[test]
    fn few_receivers_count_every_group_unsampled() {
        let mut scene = generated::subdivided_cornell_box(1_000);
        for t in (0..scene.len()).step_by(3) {
            scene.emission[t] = [1.0; 3];
            scene.triangles[t].swap(1, 2);
        }
        let patches = build_patches(&scene, None);
        let receivers = super::super::solvers::patch_receivers(&patches);
        let direct = DirectLight::new(&patches, receivers.len());
        let groups = direct.group_count() as u64;
        assert!(groups > 1 && receivers.len() as u64 * groups * 16 <= LIGHTS_UNSAMPLED_BYTES);
        let (mut lights, mut parts) = (Vec::new(), Vec::new());
        let kept: usize = (receivers.iter())
            .map(|r| {
                direct.unoccluded(r, &mut lights, &mut parts);
                lights.len()
            })
            .sum();
        let sampled = kept as f64 / receivers.len() as f64 * LIGHTS_MARGIN;
        assert!(
            sampled < 0.75 * groups as f64,
            "sampled {sampled}, groups {groups}"
        );
        assert_eq!(direct.lights_per_receiver(&receivers), groups);
    }

    #[test]
    fn direct_light_budget_counts_receivers_times_groups() {
        let patches = build_patches(&generated::cornell_box(), None);
        let direct = DirectLight::new(&patches, patches.len());
        let groups = direct.group_count() as u64;
        assert!(groups >= 1);
        assert!(!direct.over_budget(patches.len()));
        // The receivers' count alone never skips it (shadow rays at any scale).
        assert!(!direct.over_budget(4_000_000 / groups as usize));
        let limit = (DIRECT_LIGHT_BUDGET / groups) as usize;
        assert!(!direct.over_budget(limit));
        assert!(direct.over_budget(limit + 1));
    }
}

mod stats_tests {
    use super::super::*;
    use crate::mesh::build_patches;
    use crate::scene::generated;

    /// The occluder scene (a light, a plate, a floor split 12 x 12): every floor cell in the
    /// umbra or fully lit is settled by its pilot, the penumbra's cells are not, and the counts
    /// add up: every lit receiver traced at least its pilot, at most a pilot and a full pass.
    #[test]
    fn direct_stats_count_the_rays_of_the_occluder() {
        let patches = build_patches(&generated::occluder_scene(), None);
        let receivers = patch_receivers(&patches);
        let light = DirectLight::new(&patches, receivers.len());
        let (_, stats) = light.reflected(&receivers, &Progress::hidden());
        assert_eq!(stats.receivers, receivers.len() as u64);
        // The light (albedo 0) takes no ray; the plate's top and every floor cell are lit.
        assert!(stats.lit_receivers > 0 && stats.lit_receivers < stats.receivers);
        assert!(
            stats.settled_by_pilot > 0 && stats.settled_by_pilot < stats.lit_receivers,
            "{stats:?}"
        );
        let pilot = PILOT_SAMPLES as u64;
        let most = (MAX_SHADOW_SAMPLES + MAX_SHADOW_SAMPLES / 4) as u64;
        assert!(
            stats.shadow_rays >= pilot * stats.lit_receivers,
            "{stats:?}"
        );
        assert!(stats.shadow_rays <= most * stats.lit_receivers, "{stats:?}");
        // Unsettled receivers traced a full pass beyond their pilot.
        let unsettled = stats.lit_receivers - stats.settled_by_pilot;
        assert!(
            stats.shadow_rays
                >= pilot * stats.lit_receivers + MIN_SHADOW_SAMPLES as u64 * unsettled
        );
    }
}

//! The light the head sends back into the hair with multiple scattering
//! (the engine's `bounce` module): it adds the head's light, tinted by the
//! head's colour, most to the hair nearest the head, and nothing when the
//! head is black or the effect is off.

use std::path::Path;

use engine::{Scene, Sequence};
use glam::Vec3;

/// Each vertex's shaded colour and its distance from the head's centre,
/// for the smooth style lit from the front, blond, with multiple
/// scattering, the head `head` coloured and `bounce` saying
/// `effects.head_bounce`.
fn shaded(head: [f32; 3], bounce: bool) -> (Vec<Vec3>, Vec<f32>) {
    let text = format!(
        "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 96\nheight = 64\n\
         [[light]]\ndirection = [-0.2, -0.5, -1]\n\
         [head]\ncolor = [{}, {}, {}]\n\
         [shading]\nmodel = \"marschner\"\neumelanin = 0.3\nambient = 0\n\
         [effects]\nmultiple_scattering = true\nhead_bounce = {bounce}\n",
        head[0], head[1], head[2]
    );
    let scene = Scene::from_toml_str(&text, Path::new("head.toml")).unwrap();
    let mut seq = Sequence::new(&scene).unwrap();
    seq.next_frame().unwrap();
    let center = scene.head.as_ref().unwrap().center;
    let colors = seq.renderer().colors().to_vec();
    let dist = seq
        .hair()
        .points()
        .iter()
        .map(|p| (*p - center).length())
        .collect();
    (colors, dist)
}

#[test]
fn the_head_lights_the_hair_around_it_in_its_own_colour() {
    let (off, dist) = shaded([0.6, 0.1, 0.1], false);
    let (black, _) = shaded([0.0, 0.0, 0.0], true);
    let (red, _) = shaded([0.6, 0.1, 0.1], true);
    // A black head sends nothing: the same colours as with the effect off.
    assert_eq!(off, black);
    // A red head adds light everywhere it adds any, red most.
    let mut added = Vec3::ZERO;
    for (a, b) in red.iter().zip(&off) {
        assert!(a.cmpge(*b).all(), "{a} against {b}");
        added += *a - *b;
    }
    assert!(added.x > 3.0 * added.z && added.x > 0.0, "{added}");
    // Most to the hair nearest the head: the inner fifth of the vertices
    // by distance gains more, a vertex, than the outer fifth.
    let mut order: Vec<usize> = (0..dist.len()).collect();
    order.sort_by(|&i, &j| dist[i].total_cmp(&dist[j]));
    let fifth = order.len() / 5;
    let gain =
        |idx: &[usize]| idx.iter().map(|&i| (red[i] - off[i]).x).sum::<f32>() / idx.len() as f32;
    let (inner, outer) = (gain(&order[..fifth]), gain(&order[order.len() - fifth..]));
    assert!(inner > 2.0 * outer, "inner {inner}, outer {outer}");
}

/// Each vertex's shaded colour with a sky of radiance `ambient`, the sun
/// coming from -x, the head black (it sends no light back: what differs
/// between two skies is the sky's own light), and each vertex's sun's
/// transmittance.
fn under_sky(ambient: f32) -> (Vec<Vec3>, Vec<f32>) {
    let text = format!(
        "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 96\nheight = 64\n\
         [[light]]\ndirection = [1, 0, 0]\n\
         [head]\ncolor = [0, 0, 0]\n\
         [shading]\nmodel = \"marschner\"\neumelanin = 0.3\nambient = {ambient}\n\
         [effects]\nmultiple_scattering = true\n"
    );
    let scene = Scene::from_toml_str(&text, Path::new("sky.toml")).unwrap();
    let mut seq = Sequence::new(&scene).unwrap();
    seq.next_frame().unwrap();
    let colors = seq.renderer().colors().to_vec();
    (colors, seq.renderer().transmittance()[0].clone())
}

#[test]
fn the_sky_lights_the_hair_the_sun_does_not_reach() {
    let (dark, sun) = under_sky(0.0);
    let (sky, _) = under_sky(0.5);
    let gain = |keep: &dyn Fn(f32) -> bool| {
        let (mut sum, mut n) = (0.0f32, 0);
        for ((a, b), &t) in sky.iter().zip(&dark).zip(&sun) {
            if keep(t) {
                assert!((*a - *b).min_element() >= -1e-6, "{a} against {b}");
                sum += (*a - *b).element_sum();
                n += 1;
            }
        }
        assert!(n > 50, "{n} vertices");
        sum / n as f32
    };
    // Where the sun's light comes through, and where the head or the hair
    // stops it: the sky's does not stop with it (it comes from every
    // direction, through the hair about the head).
    let (lit, dark) = (gain(&|t| t > 0.5), gain(&|t| t < 1e-3));
    assert!(lit > 0.0, "{lit}");
    assert!(
        dark > 0.3 * lit,
        "in the sun's shadow {dark}, in its light {lit}"
    );
}

/// The frame's linear picture (over black) under a sky of radiance
/// `ambient`, the sun behind the head: the camera sees its shadowed side.
fn head_under_sky(ambient: f32) -> Vec<glam::Vec4> {
    let text = format!(
        "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 192\nheight = 128\n\
         [camera]\nview = \"three-quarter-left\"\n\
         [[light]]\ndirection = [0, -0.3, 1]\n\
         [head]\ncolor = [0.8, 0.8, 0.8]\n\
         [shading]\nmodel = \"marschner\"\neumelanin = 0.3\nambient = {ambient}\n\
         [effects]\nmultiple_scattering = true\n"
    );
    let scene = Scene::from_toml_str(&text, Path::new("sky.toml")).unwrap();
    let mut seq = Sequence::new(&scene).unwrap();
    seq.next_frame().unwrap();
    seq.renderer().linear_picture_over(Vec3::ZERO).unwrap()
}

#[test]
fn the_sky_lights_the_side_of_the_head_the_sun_does_not() {
    let dark = head_under_sky(0.0);
    let sky = head_under_sky(0.5);
    // The pixels the sun leaves dark (the head's own shadow, and hair
    // deep in the hair's): under the sky, the bare head among them gets
    // the sky's light, 0.5 times its colour, as in the open (before, it
    // took the sun's transmittance for the sky's: none).
    let max = dark.iter().map(|p| p.y).fold(0.0f32, f32::max);
    let mut gains: Vec<f32> = dark
        .iter()
        .zip(&sky)
        .filter(|(d, _)| d.w > 0.99 && d.y < 0.01 * max)
        .map(|(d, s)| (s.y - d.y) / (0.5 * 0.8))
        .collect();
    gains.sort_by(f32::total_cmp);
    assert!(gains.len() > 100, "{} pixels", gains.len());
    let median = gains[gains.len() / 2];
    assert!(
        median > 0.5,
        "the sky's light there: {median} of the open's"
    );
}

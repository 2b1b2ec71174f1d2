//! Self-collisions through the density map (paper 5.1): where hair is
//! denser than a threshold, it pushes hair out of the cell.

use glam::Vec3;
use shadow::{DensityMap, Fiber};

/// Repulsion from the cells of a filled density map.
///
/// A cell's optical depth `tau` (see [`shadow::DensityMap`]) is
/// `alpha * w * L / ds^2` for a length `L` of hair inside it, so its hair
/// density, length per volume, is
///
/// ```text
/// rho = tau / (alpha * w * ds)          (1 / scene units^2)
/// ```
///
/// independent of the map's resolution. A point in a cell with
/// `rho > rho_max` is pushed away from the cell's centre with acceleration
///
/// ```text
/// |a| = min(k * (rho / rho_max - 1), a_max)
/// ```
///
/// (`k` and `a_max` in scene units per s^2): bounded, and zero at or below
/// the threshold and outside the map. The push points down the density
/// slope, `-grad rho / |grad rho|` by central differences over the
/// neighbouring cells, so that hair leaves a crowd rather than shuttling
/// between the centres of two dense cells; where the neighbourhood is flat
/// it points away from the cell's centre `c`, as in the paper.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DensityRepulsion<'a> {
    map: &'a DensityMap,
    /// The map's frame, and whether its rays are parallel.
    frame: shadow::LightFrame,
    parallel: bool,
    /// `1 / (alpha * w * ds)`: from optical depth to hair density.
    to_density: f32,
    pub rho_max: f32,
    pub k: f32,
    pub a_max: f32,
}

impl<'a> DensityRepulsion<'a> {
    /// `None` when the fiber casts no shadow (`alpha * w = 0`): the map then
    /// holds no density to collide with.
    pub(crate) fn new(
        map: &'a DensityMap,
        fiber: &Fiber,
        rho_max: f32,
        k: f32,
        a_max: f32,
    ) -> Option<Self> {
        let cross = fiber.cross_section() * map.frame().ds;
        (cross > 0.0 && rho_max > 0.0).then(|| DensityRepulsion {
            map,
            frame: *map.frame(),
            parallel: map.frame().fan.is_none(),
            to_density: 1.0 / cross,
            rho_max,
            k,
            a_max,
        })
    }

    /// Hair density (length per volume) of the cell holding `p`, if inside;
    /// opaque spheres in the map (the head) do not count.
    #[cfg(test)]
    fn density_at(&self, p: Vec3) -> Option<f32> {
        self.density_in_cells(self.cells(p))
    }

    #[inline]
    fn cells(&self, p: Vec3) -> Vec3 {
        if self.parallel {
            self.frame.to_cells_parallel(p)
        } else {
            self.frame.to_cells(p)
        }
    }

    /// [`Self::density_at`] from map coordinates `c` (in cells).
    fn density_in_cells(&self, c: Vec3) -> Option<f32> {
        let n = self.frame.n_cells as f32;
        if !(c.cmpge(Vec3::ZERO).all() && c.cmplt(Vec3::splat(n)).all()) {
            return None;
        }
        let (i, j, k) = (c.x as usize, c.y as usize, c.z as usize);
        let tau = f64::from(self.map.hair_quanta(i, j, k)) * shadow::DEPTH_QUANTUM;
        if self.parallel {
            return Some(tau as f32 * self.to_density);
        }
        match &self.frame.fan {
            None => Some(tau as f32 * self.to_density),
            // A fan's cell of depth ds holds rays that cross it at
            // cos = 1 / sqrt(q): rho = tau / (alpha w ds sqrt(q)).
            Some(f) => {
                let u = f.start.y + (j as f32 + 0.5) * f.du;
                let v = f.start.z + (k as f32 + 0.5) * f.du;
                Some(tau as f32 * self.to_density / (1.0 + u * u + v * v).sqrt())
            }
        }
    }
}

impl sim::ForceField for DensityRepulsion<'_> {
    fn acceleration(&self, p: Vec3) -> Vec3 {
        let f = &self.frame;
        let c = self.cells(p);
        let Some(rho) = self.density_in_cells(c) else {
            return Vec3::ZERO;
        };
        if rho.is_nan() || rho <= self.rho_max {
            return Vec3::ZERO;
        }
        // Down the density slope: the central difference of the
        // neighbouring cells' densities (0 outside the map).
        let at = |d: Vec3| self.density_in_cells(c + d).unwrap_or(0.0);
        let grad = Vec3::new(
            at(Vec3::X) - at(Vec3::NEG_X),
            at(Vec3::Y) - at(Vec3::NEG_Y),
            at(Vec3::Z) - at(Vec3::NEG_Z),
        );
        let dir_cells = if grad.length() > 1e-3 * rho {
            -grad.normalize()
        } else {
            // A flat neighbourhood: away from the cell's centre.
            (c - (c.floor() + Vec3::splat(0.5))).normalize_or_zero()
        };
        let away = match &f.fan {
            None => dir_cells.x * f.axes[0] + dir_cells.y * f.axes[1] + dir_cells.z * f.axes[2],
            // The cells' axes differ from place to place in a fan.
            Some(_) => (f.to_world(c + 0.5 * dir_cells) - f.to_world(c)).normalize_or_zero(),
        };
        let a = (self.k * (rho / self.rho_max - 1.0)).min(self.a_max);
        away * a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shadow::{Light, LightFrame};
    use sim::ForceField;
    use strands::Hair;

    fn map_with_a_bundle() -> (DensityMap, Fiber) {
        let light = Light::directional(Vec3::NEG_Y).unwrap();
        let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 8).unwrap();
        let mut map = DensityMap::new(frame);
        let mut hair = Hair::new();
        // 50 strands along x through the cell around (0.5, 0.5, 0.5).
        for s in 0..50 {
            let o = 0.2 + 0.01 * s as f32;
            hair.push_strand(&[Vec3::new(-4.0, o, 0.5), Vec3::new(4.0, o, 0.5)])
                .unwrap();
        }
        let fiber = Fiber::new(0.01, 0.5).unwrap();
        map.fill(&hair, &fiber);
        (map, fiber)
    }

    #[test]
    fn density_is_hair_length_per_volume() {
        let (map, fiber) = map_with_a_bundle();
        let r = DensityRepulsion::new(&map, &fiber, 1.0, 100.0, 1000.0).unwrap();
        // Light travels along -y, so y is the map's depth axis: every strand
        // lies in the slice y in [0, 1). Across the light they run at z = 0.5,
        // the centre of a column, where the tent splat keeps all of a strand
        // in that column. Each cell along x then holds 50 strands of length 1
        // in a unit volume.
        let total = 50.0;
        let got = r.density_at(Vec3::new(0.5, 0.5, 0.5)).unwrap();
        assert!((got - total).abs() < 0.01 * total, "{got} vs {total}");
    }

    #[test]
    fn the_head_in_the_map_is_not_dense_hair() {
        let (mut map, fiber) = map_with_a_bundle();
        let before = DensityRepulsion::new(&map, &fiber, 1.0, 100.0, 1000.0)
            .unwrap()
            .density_at(Vec3::new(0.5, 0.5, 0.5))
            .unwrap();
        let c = map.frame().to_cells(Vec3::new(0.5, 0.5, 0.5));
        let (i, j, k) = (c.x as usize, c.y as usize, c.z as usize);
        let hair_only = map.cell_depth(i, j, k);
        // A head whose lit surface lies in the bundle's cell.
        map.deposit_body(
            &shadow::Occluder::sphere(Vec3::new(0.5, -1.4, 0.5), 2.0),
            shadow::OPAQUE_DEPTH,
        );
        assert!(
            map.cell_depth(i, j, k) > hair_only + 1.0,
            "the sphere's deposit is in the bundle's cell"
        );
        let r = DensityRepulsion::new(&map, &fiber, 1.0, 100.0, 1000.0).unwrap();
        assert_eq!(r.density_at(Vec3::new(0.5, 0.5, 0.5)).unwrap(), before);
        assert_eq!(r.density_at(Vec3::new(0.5, 3.5, 3.5)).unwrap(), 0.0);
    }

    #[test]
    fn repulsion_points_down_the_density_slope() {
        let light = Light::directional(Vec3::NEG_Y).unwrap();
        let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 8).unwrap();
        let mut map = DensityMap::new(frame);
        let fiber = Fiber::new(0.01, 0.5).unwrap();
        // Many strands at z = 0.5, fewer at z = 1.5: the crowd is at -z.
        let mut hair = Hair::new();
        for (z, count) in [(0.5, 60), (1.5, 20)] {
            for s in 0..count {
                let y = 0.2 + 0.6 * s as f32 / count as f32;
                hair.push_strand(&[Vec3::new(-4.0, y, z), Vec3::new(4.0, y, z)])
                    .unwrap();
            }
        }
        map.fill(&hair, &fiber);
        let r = DensityRepulsion::new(&map, &fiber, 10.0, 100.0, 1e6).unwrap();
        let a = r.acceleration(Vec3::new(0.5, 0.5, 1.2));
        // The neighbours: 60 strands below in z, none above: push up in z,
        // even though the point lies below its cell's centre.
        assert!(a.z > 0.0 && a.x.abs() < 1e-3 && a.y.abs() < 1e-3, "{a}");
    }

    #[test]
    fn repulsion_pushes_out_of_dense_cells_and_is_bounded() {
        let (map, fiber) = map_with_a_bundle();
        let r = DensityRepulsion::new(&map, &fiber, 5.0, 100.0, 300.0).unwrap();
        let a = r.acceleration(Vec3::new(0.9, 0.5, 0.5));
        assert!(a.x > 0.0 && a.length() <= 300.0 + 1e-3, "{a}");
        assert_eq!(
            r.acceleration(Vec3::new(0.5, 3.5, 3.5)),
            Vec3::ZERO,
            "empty cell"
        );
        assert_eq!(
            r.acceleration(Vec3::new(0.5, 50.0, 0.5)),
            Vec3::ZERO,
            "outside"
        );
        let strong = DensityRepulsion::new(&map, &fiber, 0.001, 1e9, 300.0).unwrap();
        assert!((strong.acceleration(Vec3::new(0.9, 0.5, 0.5)).length() - 300.0).abs() < 1e-2);
        let weak = DensityRepulsion::new(&map, &fiber, 1e6, 100.0, 300.0).unwrap();
        assert_eq!(
            weak.acceleration(Vec3::new(0.9, 0.5, 0.5)),
            Vec3::ZERO,
            "below threshold"
        );
    }
}

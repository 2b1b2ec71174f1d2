//! The head as it stands in a frame: a sphere, or a mesh read from OBJ or
//! PLY.

use std::sync::{Arc, OnceLock};

use glam::{Affine3A, Vec3};
use shadow::Occluder;
use strands::{Bounds, Mesh};

use crate::bounce::{HeadShape, Surface};
use crate::{EngineError, HeadSettings, Scene};

/// The scene's head, moved by the head's motion.
#[derive(Debug, Clone)]
pub struct Head {
    settings: HeadSettings,
    /// The mesh at rest, in scene units (`offset + scale * v`).
    rest: Option<Arc<Mesh>>,
    /// Where the head stands now: its transform, centre and mesh.
    pose: Affine3A,
    center: Vec3,
    posed: Option<Arc<Mesh>>,
    /// The surface around the centre at rest, found when first asked
    /// for (the head's light, [`crate::bounce`]).
    surface: OnceLock<Arc<Surface>>,
}

impl Head {
    /// The head of `settings` at rest; reads its mesh file, if any, as
    /// `scene` holds it (see [`Scene::data_file`]).
    pub fn load(settings: &HeadSettings, scene: &Scene) -> Result<Head, EngineError> {
        let rest = match &settings.mesh {
            Some(m) => {
                strands::mesh_parser(&m.path)?;
                let bytes =
                    scene
                        .data_file(&m.path)
                        .map_err(|cause| strands::MeshLoadError::Io {
                            path: m.path.clone(),
                            cause,
                        })?;
                let mesh = strands::load_mesh_bytes(&m.path, &bytes)?;
                let place = Affine3A::from_scale_rotation_translation(
                    Vec3::splat(m.scale),
                    glam::Quat::IDENTITY,
                    m.offset,
                );
                Some(Arc::new(mesh.transformed(place)))
            }
            None => None,
        };
        Ok(Head {
            settings: settings.clone(),
            pose: Affine3A::IDENTITY,
            center: settings.center,
            posed: rest.clone(),
            rest,
            surface: OnceLock::new(),
        })
    }

    /// Moves the head to `pose` (the head motion's transform); a mesh is
    /// transformed only when the pose changed.
    pub fn set_pose(&mut self, pose: Affine3A) {
        if pose == self.pose {
            return;
        }
        self.pose = pose;
        self.center = pose.transform_point3(self.settings.center);
        self.posed = self.rest.as_ref().map(|m| {
            if pose == Affine3A::IDENTITY {
                m.clone()
            } else {
                Arc::new(m.transformed(pose))
            }
        });
    }

    /// The head motion's transform it stands under.
    pub fn pose(&self) -> Affine3A {
        self.pose
    }

    /// The scene's settings of the head.
    pub fn settings(&self) -> &HeadSettings {
        &self.settings
    }

    /// The collision sphere's centre now.
    pub fn center(&self) -> Vec3 {
        self.center
    }

    /// The mesh as it stands now, if the head is one.
    pub fn mesh(&self) -> Option<&Mesh> {
        self.posed.as_deref()
    }

    /// The head's surface along the sampled directions from its centre,
    /// at rest (see [`Surface`]): made once, on first use.
    pub(crate) fn surface(&self) -> Arc<Surface> {
        self.surface
            .get_or_init(|| {
                Arc::new(match &self.rest {
                    Some(m) => Surface::mesh(m, self.settings.center),
                    None => Surface::sphere(self.settings.radius),
                })
            })
            .clone()
    }

    /// The head as it stands now, for its light on the hair.
    pub(crate) fn shape(&self) -> HeadShape {
        HeadShape::new(self.center, self.pose.matrix3, self.surface())
    }

    /// The head as an opaque body for the shadow methods.
    pub fn occluder(&self) -> Occluder {
        match &self.posed {
            Some(m) => Occluder::Mesh(m.clone()),
            None => Occluder::sphere(self.center, self.settings.radius),
        }
    }

    /// What the drawn head covers.
    pub fn bounds(&self) -> Bounds {
        self.occluder().bounds()
    }
}

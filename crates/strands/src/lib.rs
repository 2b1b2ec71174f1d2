//! Hair geometry: strands as polylines, grouped into wisps.
//!
//! This crate owns the hair as data: loading it from files (Cem Yuksel's
//! `.hair`, TressFX `.tfx`, USC-HairSalon `.data`, CT2Hair `.bin`, PLY
//! strand sets, Alembic curves, USD `BasisCurves`), growing it procedurally (the `smooth` and `curly`
//! styles of 134 wisps on a spherical head), growing follow strands around
//! guide strands, and Catmull-Rom resampling of every strand into the points
//! that are both filled into the density map and drawn. It also reads the
//! triangle meshes (Wavefront OBJ) of heads the hair grows on.
//!
//! It knows nothing of light, shadows, cameras or simulation, and does no I/O
//! beyond reading the one file a loader is given.

mod alembic;
mod catmull_rom;
mod cubic;
mod files;
mod follow;
mod hair;
mod load;
mod mesh;
mod ply;
mod rng;
mod style;
mod usd;

pub use alembic::{AlembicError, alembic_samples, parse_alembic};
pub use catmull_rom::{resample, resample_into};
pub use files::{
    LoadError, MAX_FILE_BYTES, MeshLoadError, SPECIAL_FILE_WAIT, groom_samples,
    is_animated_groom_path, is_groom_path, load, load_bytes, load_bytes_again, load_mesh,
    load_mesh_bytes, load_obj, load_obj_bytes, load_with, load_with_samples, mesh_parser,
    read_capped, read_capped_within,
};
pub use follow::{FollowParams, grow_followers};
pub use hair::{Bounds, Hair, HairError};
pub use load::{FormatError, parse_ct2hair_bin, parse_hair_format, parse_tfx, parse_usc_data};
pub use mesh::{MAX_MESH_ELEMENTS, Mesh, MeshError, parse_obj};
pub use ply::{parse_ply_mesh, parse_ply_strands};
pub use rng::Rng;
pub use style::{GUIDES_PER_WISP, Member, Style, StyleParams, WispModel};
pub use usd::{UsdError, parse_usd};

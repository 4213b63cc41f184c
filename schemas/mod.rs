//! Schemas: the periodic units of behaviour. Each is compiled in only under the
//! cargo feature of its own name.

#[cfg(feature = "calibrador")]
pub mod calibrador;
#[cfg(feature = "colortuner")]
pub mod colortuner;
#[cfg(feature = "extrinsics")]
pub mod extrinsics;
#[cfg(feature = "followball")]
pub mod followball;
#[cfg(feature = "hsvtuner")]
pub mod hsvtuner;
#[cfg(feature = "image_viewer")]
pub mod image_viewer;
#[cfg(feature = "imagerectifier")]
pub mod imagerectifier;
#[cfg(feature = "introrob")]
pub mod introrob;
#[cfg(feature = "mastergui")]
pub mod mastergui;
#[cfg(feature = "myschema")]
pub mod myschema;
#[cfg(feature = "naooperator")]
pub mod naooperator;
#[cfg(feature = "opencvdemo")]
pub mod opencvdemo;
#[cfg(feature = "opengl_viewer")]
pub mod opengl_viewer;
#[cfg(feature = "opengldemo")]
pub mod opengldemo;
#[cfg(feature = "pingpong")]
pub mod pingpong;
#[cfg(feature = "python")]
pub mod python;
#[cfg(feature = "teleoperator")]
pub mod teleoperator;

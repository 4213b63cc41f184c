//! Colour blobs seen by a camera's blob finder (Player's blobfinder today), as a
//! driver exports them in the name space: under `DRIVER.blobs` (`player.blobs`,
//! `player.blobs.ROBOT` for a robot suffix) an `ArcSwap<BlobFrame>` that readers
//! load without waiting.

use arc_swap::ArcSwap;

/// One blob.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Blob {
    /// The finder's id for it (Player/Stage may leave it uninitialised).
    pub id: u32,
    /// Colour, 0xRRGGBB.
    pub color: u32,
    /// Pixels.
    pub area: u32,
    /// Centroid, pixels.
    pub x: u32,
    pub y: u32,
    /// Bounding box, pixels.
    pub left: u32,
    pub right: u32,
    pub top: u32,
    pub bottom: u32,
    /// mm.
    pub range: f32,
}

/// The latest blobfinder frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BlobFrame {
    /// Increases with every frame (0: none yet).
    pub clock: u64,
    /// The blobfinder's image size, pixels.
    pub width: u32,
    pub height: u32,
    pub blobs: Vec<Blob>,
}

/// What the driver exports as `player.blobs`: the latest frame; readers never wait.
pub type LiveBlobs = ArcSwap<BlobFrame>;

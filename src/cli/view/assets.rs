//! The page's files, built into the binary: the viewer page and script (`web/`) and the
//! pinned three.js release with its orbit controls (`web/vendor/three-0.170.0/`, MIT
//! licence beside them; `scripts/vendor-three.sh` re-fetches and checks them).

/// The page.
pub const INDEX_HTML: &str = include_str!("../../../web/index.html");
/// The page's script.
pub const APP_JS: &str = include_str!("../../../web/app.js");
/// The page's occlusion culling (imported by the script).
pub const OCCLUSION_JS: &str = include_str!("../../../web/occlusion.js");
/// Where the page loads three.js from (its import map names it).
pub const THREE_PATH: &str = "/vendor/three-0.170.0/three.module.min.js";
/// three.js 0.170.0.
pub const THREE_JS: &str = include_str!("../../../web/vendor/three-0.170.0/three.module.min.js");
/// Where the page loads the orbit controls from.
pub const ORBIT_PATH: &str = "/vendor/three-0.170.0/OrbitControls.js";
/// three.js 0.170.0's orbit controls.
pub const ORBIT_CONTROLS_JS: &str =
    include_str!("../../../web/vendor/three-0.170.0/OrbitControls.js");

//! Empty on purpose: this crate exists for its build script, which links the static glslang
//! libraries that `shaderc` (prefer-static-linking, against Debian's libshaderc) leaves undefined.

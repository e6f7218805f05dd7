//! See the module docs of `background`.

//! Universal file format dataset 58 (ASCII and binary 58b).

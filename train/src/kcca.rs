//! kcca

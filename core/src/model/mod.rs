//! The model file and what it stores.

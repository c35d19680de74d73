//! The model container: a trained model (`.crease`) and a rig (`.rig`) from the same bytes
//! (both start with the container's sections). An accepted model must predict a frame at
//! rest without panicking.
#![no_main]
use crease_core::model::{Rig, TrainedModel};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = Rig::from_bytes(data);
    if let Ok(model) = TrainedModel::from_bytes(data) {
        // A round trip must give the same model back.
        let bytes = model.to_bytes().expect("an accepted model writes");
        let again = TrainedModel::from_bytes(&bytes).expect("a written model reads");
        assert_eq!(again.to_bytes().expect("writes"), bytes);
    }
});

//! What both fuzz targets share.

/// Panics inside the Draco decoder (an alpha, third-party) are caught by mesa, which turns them
/// into a `draco` error (`stages/src/glb_read/draco.rs`); libFuzzer's hook would abort on them
/// before they unwind. Every other panic still aborts: it is a bug. A panic is the decoder's
/// when the decoder is on the stack: its own code, or the standard library called from it
/// (`clamp`'s assertion reports core's file as its location).
pub fn let_draco_panics_unwind() {
    let abort = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let in_draco = info
            .location()
            .is_some_and(|l| l.file().contains("/draco-oxide-"))
            || std::backtrace::Backtrace::force_capture()
                .to_string()
                .contains("draco_oxide_decoder::");
        if !in_draco {
            abort(info);
        }
    }));
}

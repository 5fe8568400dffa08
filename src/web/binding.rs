//! What every binding shares (wasm32): the start hook that routes a Rust panic to the console,
//! and the error a binding throws to the page.

/// An error of the core as the exception a binding throws to the page.
pub fn js_err(e: impl std::fmt::Display) -> wasm_bindgen::JsError {
    wasm_bindgen::JsError::new(&e.to_string())
}

/// Runs once when the module is instantiated: a Rust panic then reaches the console with its
/// message, and the page (which wraps every call) shows it instead of freezing silently.
#[wasm_bindgen::prelude::wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

/// How many threads run the core's parallel loops: 1 in the single-thread build; in the
/// threaded one (feature `threads`), the workers of the pool that `initThreadPool(n)` started
/// (the worker that calls the core waits while they work).
#[wasm_bindgen::prelude::wasm_bindgen(js_name = coreThreads)]
pub fn core_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

//! The code version the page names in its share links and downloads (`codeVersion`): the one
//! of every file this program writes ([`crate::formats::code_version`]), e.g. `0.1.0+f1cefbb1a2b3`.

/// `<crate version>+<git commit>`.
#[cfg_attr(target_arch = "wasm32", wasm_bindgen::prelude::wasm_bindgen(js_name = codeVersion))]
pub fn code_version() -> String {
    crate::formats::code_version()
}

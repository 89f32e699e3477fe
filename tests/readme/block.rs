//! The README's walk-throughs are followed literally: a section's `rust`
//! code block must be, to the letter, the file a test compiles.

/// Assert that the first `rust` block after `section` in the README at
/// `readme` is the text of `file`.
pub fn assert_block_is_file(readme: &str, section: &str, file: &str) {
    let text = std::fs::read_to_string(readme).unwrap_or_else(|e| panic!("{readme}: {e}"));
    let at = text
        .find(section)
        .unwrap_or_else(|| panic!("README has no `{section}`"));
    let rest = &text[at..];
    let start = rest.find("```rust\n").expect("a rust block in the section") + "```rust\n".len();
    let len = rest[start..].find("```\n").expect("the block ends");
    let want = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{file}: {e}"));
    assert_eq!(
        &rest[start..start + len],
        want,
        "README's `{section}` example and {file} differ"
    );
}

//! The `mtllib` statement of OBJ files: which material files a line names. Shared by the OBJ
//! loader, the OBJ texture reader and the mesh variants' material files.

use std::path::Path;

/// The file names one `mtllib` statement's argument names, relative to `dir`: `mtllib a.mtl
/// b.mtl` names several files, unless a file of that whole name exists.
pub(crate) fn names<'a>(dir: &Path, argument: &'a str) -> Vec<&'a str> {
    if dir.join(argument).is_file() || !argument.contains(char::is_whitespace) {
        vec![argument]
    } else {
        argument.split_whitespace().collect()
    }
}

/// The argument of an OBJ line if it is an `mtllib` statement (comment and surrounding blanks
/// removed), else `None`. [`names`] splits it into file names.
pub(crate) fn argument(raw: &str) -> Option<&str> {
    let line = raw.split('#').next().unwrap_or("").trim();
    let rest = line.strip_prefix("mtllib")?;
    rest.starts_with(char::is_whitespace).then(|| rest.trim())
}

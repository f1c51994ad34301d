//! Loading an ESI file for a command: `FILE.xml[#SEL]` (the selector syntax of
//! [`fieldprobe::esi::select`]), the reader's warnings and the selection's notes on stderr.
//!
//! Every command that loads an ESI goes through [`load`], which prints each of the file's
//! warnings once as `warning: file:line:col: path: …`, and through [`choose`] when it needs one
//! device, which prints the selection's notes as `note: …`.

use fieldprobe::esi::{self, EsiFile, Resolved, Selector};
use std::path::{Path, PathBuf};

/// `FILE.xml[#SEL]` → (file, selector text). A spec that names an existing file is a file name
/// even when it contains `#`.
pub(crate) fn split(spec: &str) -> (PathBuf, Option<String>) {
    if Path::new(spec).is_file() {
        return (PathBuf::from(spec), None);
    }
    let (file, sel) = esi::split_spec(spec);
    (PathBuf::from(file), sel.map(str::to_string))
}

/// Read and parse an ESI file; its warnings go to stderr, once.
pub(crate) fn load(path: &Path) -> anyhow::Result<EsiFile> {
    let file = esi::load(path)?;
    for w in &file.warnings {
        eprintln!("warning: {w}");
    }
    Ok(file)
}

/// The selector of a command: from `FILE#SEL` or from its `--device SEL` option (both: they
/// must agree).
pub(crate) fn selector(
    from_spec: Option<&str>,
    option: Option<&str>,
) -> anyhow::Result<Option<Selector>> {
    let text = match (from_spec, option) {
        (Some(a), Some(b)) if a.trim() != b.trim() => {
            anyhow::bail!("the device is named twice: FILE#{a} and --device {b}; give it once")
        }
        (Some(a), _) => Some(a),
        (None, b) => b,
    };
    Ok(text.map(str::parse::<Selector>).transpose()?)
}

/// The device `sel` names, resolved with its modules; the notes go to stderr.
pub(crate) fn choose(file: &EsiFile, sel: Option<&Selector>) -> anyhow::Result<Resolved> {
    let r = esi::resolve(file, sel)?;
    for n in &r.notes {
        eprintln!("note: {n}");
    }
    Ok(r)
}

/// [`split`], [`load`], [`selector`] and [`choose`] in one: the device of `FILE.xml[#SEL]`
/// (or of `--device SEL`).
pub(crate) fn load_device(spec: &str, option: Option<&str>) -> anyhow::Result<(EsiFile, Resolved)> {
    let (path, sel) = split(spec);
    let file = load(&path)?;
    let sel = selector(sel.as_deref(), option)?;
    let device = choose(&file, sel.as_ref())?;
    Ok((file, device))
}

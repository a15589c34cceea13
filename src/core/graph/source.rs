//! Where ids, parameters and links are written in a graph's text, for error positions.

use super::problem::Place;

/// Finds where ids, parameters and links are written, for error positions. RON values carry
/// no spans, so this scans the text once, skipping comments, for the string keys (decoded, with
/// their nesting depth: node ids sit directly in the `nodes` map, parameter names two levels
/// deeper) and the entries of the `links` list.
pub(super) struct SourceMap<'a> {
    source: &'a str,
    /// Every string literal followed by `:`, as (offset, depth, value).
    keys: Vec<(usize, usize, String)>,
    /// Where each entry of the top-level `links` list starts.
    links: Vec<usize>,
}

/// The depth of node ids: inside the graph's `(` and the `nodes` map's `{`.
const NODE_DEPTH: usize = 2;
/// The depth of parameter names: inside the node's `(` and its `params` map's `{`.
const PARAM_DEPTH: usize = 4;

impl<'a> SourceMap<'a> {
    pub(super) fn new(source: &'a str) -> Self {
        let b = source.as_bytes();
        let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
        let (mut keys, mut links) = (Vec::new(), Vec::new());
        let (mut i, mut depth) = (0, 0usize);
        // After the top-level `links` key: waiting for its list, then inside it.
        let (mut links_key, mut in_links) = (false, false);
        while i < b.len() {
            let c = b[i];
            // (Identifiers are skipped whole, so an `r` inside one does not start a raw string.)
            if let Some(end) = string_end(b, i) {
                if b.get(skip_trivia(b, end)) == Some(&b':')
                    && let Ok(value) = ron::from_str::<String>(&source[i..end])
                {
                    keys.push((i, depth, value));
                }
                i = end;
                continue;
            }
            match c {
                b'/' if matches!(b.get(i + 1), Some(b'/' | b'*')) => {
                    i = skip_trivia(b, i);
                    continue;
                }
                b'(' | b'[' | b'{' => {
                    if c == b'(' && in_links && depth == 2 {
                        links.push(i);
                    }
                    if c == b'[' && links_key && depth == 1 {
                        (links_key, in_links) = (false, true);
                    }
                    depth += 1;
                }
                b')' | b']' | b'}' => {
                    depth = depth.saturating_sub(1);
                    if depth == 1 {
                        in_links = false;
                    }
                }
                _ if ident(c) => {
                    let start = i;
                    while i < b.len() && ident(b[i]) {
                        i += 1;
                    }
                    if depth == 1 && &b[start..i] == b"links" {
                        links_key = true;
                    }
                    continue;
                }
                _ => {}
            }
            i += 1;
        }
        SourceMap { source, keys, links }
    }

    pub(super) fn locate(&self, place: &Place) -> (usize, usize) {
        let offset = match place {
            Place::File => Some(0),
            Place::Node(id) => self.node_offsets(id).next(),
            // A repeated id keeps its last entry, so look in every entry written with that id.
            Place::Param(id, name) => self.node_offsets(id).find_map(|start| {
                let end =
                    self.keys.iter().find(|k| k.0 > start && k.1 == NODE_DEPTH).map_or(self.source.len(), |k| k.0);
                self.keys
                    .iter()
                    .find(|k| (start..end).contains(&k.0) && k.1 == PARAM_DEPTH && k.2 == *name)
                    .map(|k| k.0)
            }),
            Place::Link(i) => self.links.get(*i).copied(),
        };
        self.line_col(offset.unwrap_or(0))
    }

    /// Where each entry of the node `id` starts (more than one if the id is repeated).
    fn node_offsets(&self, id: &str) -> impl Iterator<Item = usize> {
        self.keys.iter().filter(move |k| k.1 == NODE_DEPTH && k.2 == id).map(|k| k.0)
    }

    pub(super) fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.source[..offset.min(self.source.len())];
        let line = before.matches('\n').count() + 1;
        let col = before.rfind('\n').map_or(before.chars().count(), |nl| before[nl + 1..].chars().count()) + 1;
        (line, col)
    }
}

/// The end of the string literal (`"..."` or `r#"..."#`) that starts at `i`, if one does.
fn string_end(b: &[u8], i: usize) -> Option<usize> {
    match b[i] {
        b'"' => {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            Some((j + 1).min(b.len()))
        }
        b'r' => {
            let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
            if b.get(i + 1 + hashes) != Some(&b'"') {
                return None;
            }
            let close: Vec<u8> = std::iter::once(b'"').chain(std::iter::repeat_n(b'#', hashes)).collect();
            let body = i + 2 + hashes;
            let end = b[body..].windows(close.len()).position(|w| w == close.as_slice());
            Some(end.map_or(b.len(), |e| body + e + close.len()))
        }
        _ => None,
    }
}

/// The offset of the first byte at or after `i` that is not white space or in a comment.
fn skip_trivia(b: &[u8], mut i: usize) -> usize {
    loop {
        match (b.get(i), b.get(i + 1)) {
            (Some(c), _) if c.is_ascii_whitespace() => i += 1,
            (Some(b'/'), Some(b'/')) => i = b[i..].iter().position(|&c| c == b'\n').map_or(b.len(), |n| i + n),
            (Some(b'/'), Some(b'*')) => {
                // Block comments nest.
                let mut depth = 0;
                while i < b.len() {
                    if b[i..].starts_with(b"/*") {
                        (depth, i) = (depth + 1, i + 2);
                    } else if b[i..].starts_with(b"*/") {
                        (depth, i) = (depth - 1, i + 2);
                        if depth == 0 {
                            break;
                        }
                    } else {
                        i += 1;
                    }
                }
            }
            _ => return i,
        }
    }
}

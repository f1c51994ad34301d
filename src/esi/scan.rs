//! Text scans of ESI documents that need no parsed model: the element path of a node for
//! messages, and two linear scans that run before (or after a failure of) the XML parser.

use roxmltree::Node;

/// `EtherCATInfo/Descriptions/Devices/Device[2]/RxPdo[1]/Entry[3]`: the element names from the
/// root, with a 1-based position where a parent has more than one child of that name.
pub(crate) fn element_path(node: Node) -> String {
    let mut parts: Vec<String> = node
        .ancestors()
        .filter(|n| n.is_element())
        .map(|n| {
            let name = n.tag_name().name();
            let same = |s: &Node| s.is_element() && s.tag_name().name() == name;
            let before = n.prev_siblings().skip(1).filter(same).count();
            let after = n.next_siblings().skip(1).filter(same).count();
            if before + after > 0 {
                format!("{name}[{}]", before + 1)
            } else {
                name.to_string()
            }
        })
        .collect();
    parts.reverse();
    parts.join("/")
}

/// Best-effort path of the elements still open at the end of `text` (`EtherCATInfo/Vendor`),
/// for the message about a truncated file. A plain tag scan: comments, CDATA, processing
/// instructions and declarations are skipped; it is only used when the XML parser has already
/// failed.
pub(crate) fn open_elements(text: &str) -> String {
    let mut stack: Vec<&str> = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find('<') {
        rest = &rest[i..];
        let skip_to = |rest: &str, end: &str| rest.find(end).map(|j| j + end.len());
        let next = if rest.starts_with("<!--") {
            skip_to(rest, "-->")
        } else if rest.starts_with("<![CDATA[") {
            skip_to(rest, "]]>")
        } else if rest.starts_with("<?") {
            skip_to(rest, "?>")
        } else if rest.starts_with("<!") {
            skip_to(rest, ">")
        } else {
            let end = rest.find('>');
            let tag = &rest[1..end.unwrap_or(rest.len())];
            let name_end = tag
                .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
                .unwrap_or(tag.len());
            if let Some(closing) = tag.strip_prefix('/') {
                let name = closing.trim();
                if stack.last() == Some(&name) {
                    stack.pop();
                }
            } else if end.is_some() && !tag.ends_with('/') && name_end > 0 {
                stack.push(&tag[..name_end]);
            } else if end.is_none() && name_end > 0 {
                // cut inside a start tag
                stack.push(&tag[..name_end]);
            }
            end.map(|j| j + 1)
        };
        match next {
            Some(n) => rest = &rest[n..],
            None => break,
        }
    }
    stack.join("/")
}

/// The first start tag with more than `max` attributes: (byte offset of its `<`, its name).
/// A linear scan that runs before the XML parser, whose duplicate-attribute check is quadratic
/// in the number of attributes of one element (100,000 attributes took 18 s). Comments, CDATA,
/// processing instructions and declarations are skipped; quoted attribute values may contain
/// `=` and `>`.
pub(crate) fn too_many_attributes(text: &str, max: usize) -> Option<(usize, &str)> {
    let bytes = text.as_bytes();
    let mut i = 0;
    while let Some(k) = text[i..].find('<') {
        let start = i + k;
        let rest = &text[start..];
        let skip_to = |end: &str| rest.find(end).map(|j| start + j + end.len());
        let next = if rest.starts_with("<!--") {
            skip_to("-->")
        } else if rest.starts_with("<![CDATA[") {
            skip_to("]]>")
        } else if rest.starts_with("<?") {
            skip_to("?>")
        } else if rest.starts_with("<!") || rest.starts_with("</") {
            skip_to(">")
        } else {
            // A start tag: count `=` outside quoted values up to its `>`.
            let mut quote: Option<u8> = None;
            let mut count = 0usize;
            let mut j = start + 1;
            let mut end = None;
            while j < bytes.len() {
                let b = bytes[j];
                match quote {
                    Some(q) if b == q => quote = None,
                    Some(_) => {}
                    None if b == b'"' || b == b'\'' => quote = Some(b),
                    None if b == b'=' => count += 1,
                    None if b == b'>' => {
                        end = Some(j + 1);
                        break;
                    }
                    None => {}
                }
                j += 1;
            }
            if count > max {
                let tag = &text[start + 1..];
                let name_end = tag
                    .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
                    .unwrap_or(tag.len());
                return Some((start, &tag[..name_end]));
            }
            end
        };
        match next {
            Some(n) => i = n,
            None => break,
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use roxmltree::Document;

    #[test]
    fn attribute_count_scan() {
        let t =
            r#"<?xml version="1.0"?><!-- a=1 b=2 c=3 --><A x="=" y='>'><B p="1" q="2" r="3"/></A>"#;
        assert_eq!(too_many_attributes(t, 3), None);
        assert_eq!(
            too_many_attributes(t, 2),
            Some((t.find("<B").unwrap(), "B"))
        );
        assert_eq!(too_many_attributes("<![CDATA[<C a=1 b=2>]]><D/>", 1), None);
    }

    #[test]
    fn open_elements_at_cut() {
        assert_eq!(
            open_elements("<?xml?><A><!-- <X> --><B/><C x=\"1\"><D>t</D><E"),
            "A/C/E"
        );
        assert_eq!(open_elements("<A></A>"), "");
        assert_eq!(open_elements("<A><![CDATA[<B>"), "A");
    }

    #[test]
    fn path_names_positions() {
        let doc = Document::parse("<A><B/><B><C/></B></A>").unwrap();
        let c = doc.descendants().find(|n| n.has_tag_name("C")).unwrap();
        assert_eq!(element_path(c), "A/B[2]/C");
    }
}

//! A typed document (headings, paragraphs, lists, tables) and its two renderings, Markdown and
//! HTML. The harness builds `tables.md` and `docs/claims.md` as a [`Doc`]; the report renders
//! the same value into `report.html`, so no page parses Markdown back.
//!
//! Text in a block is inline Markdown: `` `code` `` and `**bold**` spans, nothing else. The
//! Markdown rendering writes it as is (a table cell's `|` escaped, line breaks folded into
//! spaces); the HTML rendering escapes every character HTML gives a meaning to (text from plan
//! files reaches these pages) and turns the two spans into `<code>` and `<b>`.

use std::fmt::Write as _;

/// One block of a [`Doc`].
#[derive(Clone, Debug, PartialEq)]
pub enum Block {
    /// A heading of level 1 to 3 (`#`, `##`, `###`).
    Heading(u8, String),
    /// A paragraph, one line of inline Markdown.
    Paragraph(String),
    /// A bulleted list, one item per entry.
    List(Vec<String>),
    Table(Table),
}

/// A table: a header row, one alignment per column, body rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    pub head: Vec<String>,
    /// `true`: the column is right-aligned (numbers).
    pub right: Vec<bool>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with these columns (`(title, right-aligned)`) and no rows yet.
    pub fn new(columns: &[(&str, bool)]) -> Self {
        Table {
            head: columns.iter().map(|c| c.0.to_string()).collect(),
            right: columns.iter().map(|c| c.1).collect(),
            rows: Vec::new(),
        }
    }

    /// Append a row.
    pub fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }
}

/// A document: blocks in reading order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Doc {
    pub blocks: Vec<Block>,
}

/// A Markdown table cell: `|` and line breaks would end the cell or the row.
fn md_cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// One line of Markdown: line breaks folded into spaces.
fn md_line(s: &str) -> String {
    s.replace(['\n', '\r'], " ")
}

/// Text escaped for HTML and SVG (element content and attribute values).
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// Inline Markdown to HTML: escaped, `` ` `` and `**` spans as `<code>` and `<b>` (a span left
/// open is closed at the end).
fn inline_html(t: &str) -> String {
    let e = escape(t);
    let mut out = String::with_capacity(e.len());
    let (mut code, mut bold) = (false, false);
    let mut rest = e.as_str();
    while let Some(c) = rest.chars().next() {
        if let Some(r) = rest.strip_prefix("**") {
            out.push_str(if bold { "</b>" } else { "<b>" });
            bold = !bold;
            rest = r;
        } else {
            if c == '`' {
                out.push_str(if code { "</code>" } else { "<code>" });
                code = !code;
            } else {
                out.push(c);
            }
            rest = &rest[c.len_utf8()..];
        }
    }
    if code {
        out.push_str("</code>");
    }
    if bold {
        out.push_str("</b>");
    }
    out
}

impl Doc {
    pub fn new() -> Self {
        Doc::default()
    }

    /// Append a heading of `level` (1-3).
    pub fn heading(&mut self, level: u8, text: impl Into<String>) {
        self.blocks
            .push(Block::Heading(level.clamp(1, 3), text.into()));
    }

    /// Append a paragraph.
    pub fn para(&mut self, text: impl Into<String>) {
        self.blocks.push(Block::Paragraph(text.into()));
    }

    /// Append a list.
    pub fn list(&mut self, items: Vec<String>) {
        self.blocks.push(Block::List(items));
    }

    /// Append a table.
    pub fn table(&mut self, t: Table) {
        self.blocks.push(Block::Table(t));
    }

    /// Append every block of `other`.
    pub fn append(&mut self, other: Doc) {
        self.blocks.extend(other.blocks);
    }

    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }

    /// Markdown: blocks separated by one empty line, the text ending with one line break.
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        for (i, b) in self.blocks.iter().enumerate() {
            if i > 0 {
                s.push('\n');
            }
            match b {
                Block::Heading(l, t) => {
                    let _ = writeln!(s, "{} {}", "#".repeat(*l as usize), md_line(t));
                }
                Block::Paragraph(t) => {
                    let _ = writeln!(s, "{}", md_line(t));
                }
                Block::List(items) => {
                    for it in items {
                        let _ = writeln!(s, "- {}", md_line(it));
                    }
                }
                Block::Table(t) => {
                    let row = |cells: &[String]| -> String {
                        let mut r = String::from("|");
                        for c in cells {
                            if c.is_empty() {
                                r.push_str(" |");
                            } else {
                                let _ = write!(r, " {} |", md_cell(c));
                            }
                        }
                        r
                    };
                    let _ = writeln!(s, "{}", row(&t.head));
                    s.push('|');
                    for &r in &t.right {
                        s.push_str(if r { "---:|" } else { "---|" });
                    }
                    s.push('\n');
                    for r in &t.rows {
                        let _ = writeln!(s, "{}", row(r));
                    }
                }
            }
        }
        s
    }

    /// HTML (a fragment for a page's body): `<h1>`-`<h3>`, `<p>`, `<ul>`, `<table>` with the
    /// header row in `<th>` and right-aligned columns marked `class="r"`.
    pub fn to_html(&self) -> String {
        let mut h = String::new();
        for b in &self.blocks {
            match b {
                Block::Heading(l, t) => {
                    let _ = writeln!(h, "<h{l}>{}</h{l}>", inline_html(t));
                }
                Block::Paragraph(t) => {
                    let _ = writeln!(h, "<p>{}</p>", inline_html(t));
                }
                Block::List(items) => {
                    h.push_str("<ul>\n");
                    for it in items {
                        let _ = writeln!(h, "<li>{}</li>", inline_html(it));
                    }
                    h.push_str("</ul>\n");
                }
                Block::Table(t) => {
                    h.push_str("<table>\n<tr>");
                    let class = |j: usize| {
                        if t.right.get(j).copied().unwrap_or(false) {
                            " class=\"r\""
                        } else {
                            ""
                        }
                    };
                    for (j, c) in t.head.iter().enumerate() {
                        let _ = write!(h, "<th{}>{}</th>", class(j), inline_html(c));
                    }
                    h.push_str("</tr>\n");
                    for r in &t.rows {
                        h.push_str("<tr>");
                        for (j, c) in r.iter().enumerate() {
                            let _ = write!(h, "<td{}>{}</td>", class(j), inline_html(c));
                        }
                        h.push_str("</tr>\n");
                    }
                    h.push_str("</table>\n");
                }
            }
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Doc {
        let mut d = Doc::new();
        d.heading(1, "`T` one");
        d.para("Text with **bold** and `a | b`.");
        let mut t = Table::new(&[("name", false), ("value", true)]);
        t.row(vec!["x|y".into(), "**1**".into()]);
        t.row(vec!["line\nbreak".into(), "2".into()]);
        t.row(vec!["".into(), "".into()]);
        d.table(t);
        d.list(vec!["`c` & d".into(), "<e>".into()]);
        d.heading(3, "Three");
        d
    }

    #[test]
    fn markdown_separates_blocks_by_one_empty_line_and_escapes_cells() {
        assert_eq!(
            sample().to_markdown(),
            "# `T` one\n\nText with **bold** and `a | b`.\n\n| name | value |\n|---|---:|\n\
             | x\\|y | **1** |\n| line break | 2 |\n| | |\n\n- `c` & d\n- <e>\n\n### Three\n"
        );
        assert_eq!(Doc::new().to_markdown(), "");
    }

    #[test]
    fn html_escapes_every_text_and_marks_the_spans_and_columns() {
        assert_eq!(
            sample().to_html(),
            "<h1><code>T</code> one</h1>\n<p>Text with <b>bold</b> and <code>a | b</code>.</p>\n\
             <table>\n<tr><th>name</th><th class=\"r\">value</th></tr>\n\
             <tr><td>x|y</td><td class=\"r\"><b>1</b></td></tr>\n\
             <tr><td>line\nbreak</td><td class=\"r\">2</td></tr>\n\
             <tr><td></td><td class=\"r\"></td></tr>\n</table>\n\
             <ul>\n<li><code>c</code> &amp; d</li>\n<li>&lt;e&gt;</li>\n</ul>\n<h3>Three</h3>\n"
        );
    }

    #[test]
    fn a_hostile_text_cannot_open_an_element() {
        let mut d = Doc::new();
        d.para("<script>alert(\"x\")</script> ' `<img src=x>` **<b>");
        let h = d.to_html();
        assert!(
            !h.contains("<script") && !h.contains("<img") && !h.contains("<b><b>"),
            "{h}"
        );
        assert!(
            h.contains("&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; &#39;"),
            "{h}"
        );
        // An unclosed span is closed at the end.
        assert!(h.ends_with("<b>&lt;b&gt;</b></p>\n"), "{h}");
        // Headings are levels 1-3 only.
        let mut d = Doc::new();
        d.heading(9, "x");
        d.heading(0, "y");
        assert_eq!(d.to_markdown(), "### x\n\n# y\n");
    }
}

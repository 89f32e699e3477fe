//! A tiny document model written once and rendered to both `report.md` and a
//! self-contained `index.html`, so the two pages always say the same thing.

use crate::format::{html_escape, md_escape};

/// A table cell: text, optionally bold (the best value of its column).
#[derive(Debug, Clone, Default)]
pub(crate) struct Cell {
    pub text: String,
    pub bold: bool,
    /// Shown in a muted/warning colour in HTML (non-ok runs).
    pub warn: bool,
    /// A link target for the text (a run's folder, a section's `#anchor`).
    pub link: Option<String>,
}

impl Cell {
    pub(crate) fn plain(text: impl Into<String>) -> Self {
        Cell {
            text: text.into(),
            ..Cell::default()
        }
    }

    /// This cell with its text linking to `href`.
    pub(crate) fn linked(self, href: impl Into<String>) -> Self {
        Cell {
            link: Some(href.into()),
            ..self
        }
    }
}

/// One block of a page.
#[derive(Debug, Clone)]
pub(crate) enum Block {
    Heading(u8, String),
    /// A heading with an anchor id that the contents and links point to.
    Anchored(u8, String, String),
    /// The page's contents: filled by [`fill_toc`] with a link to every
    /// level-2 [`Block::Anchored`] heading of the page.
    Toc(Vec<(String, String)>),
    Para(String),
    Warning(String),
    List(Vec<String>),
    Table {
        header: Vec<String>,
        rows: Vec<Vec<Cell>>,
    },
    /// An image: SVG path relative to the page, PNG path, alt text.
    Image {
        svg: String,
        png: String,
        alt: String,
    },
}

/// Fills every [`Block::Toc`] of `blocks` with the level-2 anchored
/// headings of the page, in page order.
pub(crate) fn fill_toc(blocks: &mut [Block]) {
    let links: Vec<(String, String)> = blocks
        .iter()
        .filter_map(|b| match b {
            Block::Anchored(2, t, id) => Some((id.clone(), t.clone())),
            _ => None,
        })
        .collect();
    for b in blocks.iter_mut() {
        if let Block::Toc(l) = b {
            l.clone_from(&links);
        }
    }
}

/// Renders `blocks` as GitHub-flavoured markdown.
pub(crate) fn to_markdown(blocks: &[Block]) -> String {
    let mut out = String::new();
    for b in blocks {
        match b {
            Block::Heading(level, t) => {
                out.push_str(&"#".repeat(*level as usize));
                out.push(' ');
                out.push_str(&md_escape(t));
                out.push_str("\n\n");
            }
            Block::Anchored(level, t, id) => {
                out.push_str(&format!("<a id=\"{}\"></a>\n\n", html_escape(id)));
                out.push_str(&"#".repeat(*level as usize));
                out.push(' ');
                out.push_str(&md_escape(t));
                out.push_str("\n\n");
            }
            Block::Toc(links) => {
                for (id, t) in links {
                    out.push_str(&format!("- [{}](#{id})\n", md_escape(t)));
                }
                out.push('\n');
            }
            Block::Para(t) => {
                out.push_str(&md_escape(t));
                out.push_str("\n\n");
            }
            Block::Warning(t) => {
                out.push_str("> **Warning:** ");
                out.push_str(&md_escape(t));
                out.push_str("\n\n");
            }
            Block::List(items) => {
                for i in items {
                    out.push_str("- ");
                    out.push_str(&md_escape(i));
                    out.push('\n');
                }
                out.push('\n');
            }
            Block::Table { header, rows } => {
                out.push('|');
                for h in header {
                    out.push_str(&format!(" {} |", md_escape(h)));
                }
                out.push_str("\n|");
                for _ in header {
                    out.push_str("---|");
                }
                out.push('\n');
                for r in rows {
                    out.push('|');
                    for c in r {
                        let t = match &c.link {
                            Some(href) if !c.text.is_empty() => format!("[{}]({href})", md_escape(&c.text)),
                            _ => md_escape(&c.text),
                        };
                        if c.bold && !t.is_empty() {
                            out.push_str(&format!(" **{t}** |"));
                        } else {
                            out.push_str(&format!(" {t} |"));
                        }
                    }
                    out.push('\n');
                }
                out.push('\n');
            }
            Block::Image { svg, png, alt } => {
                out.push_str(&format!("![{}]({}) ([PNG]({}))\n\n", md_escape(alt), svg, png));
            }
        }
    }
    out
}

const CSS: &str = "body{font-family:'DejaVu Sans',Verdana,sans-serif;max-width:1250px;margin:2em auto;padding:0 1em;color:#111;line-height:1.4}
h1{border-bottom:2px solid #333}h2{border-bottom:1px solid #aaa;margin-top:2em}
table{border-collapse:collapse;margin:0.8em 0;font-size:0.92em}
th,td{border:1px solid #bbb;padding:3px 7px;text-align:left;vertical-align:top;overflow-wrap:break-word}
th{background:#eee}td.warn{color:#a40000}tr:nth-child(even){background:#fafafa}
.warning{background:#fff3cd;border:1px solid #e0b000;padding:0.6em 1em}
.scroll{overflow-x:auto}img{max-width:100%;height:auto;border:1px solid #ddd;margin:0.5em 0}
figure{margin:1em 0}figcaption{font-size:0.9em;color:#444}
nav ul{columns:3;font-size:0.92em}a{color:#0645ad}";

/// Renders `blocks` as a self-contained HTML page (inline CSS, SVG images linked).
pub(crate) fn to_html(title: &str, blocks: &[Block]) -> String {
    let mut out = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>\n{}\n</style>\n</head>\n<body>\n",
        html_escape(title),
        CSS
    );
    for b in blocks {
        match b {
            Block::Heading(level, t) => {
                out.push_str(&format!("<h{level}>{}</h{level}>\n", html_escape(t)));
            }
            Block::Anchored(level, t, id) => {
                out.push_str(&format!(
                    "<h{level} id=\"{}\">{}</h{level}>\n",
                    html_escape(id),
                    html_escape(t)
                ));
            }
            Block::Toc(links) => {
                out.push_str("<nav><ul>\n");
                for (id, t) in links {
                    out.push_str(&format!(
                        "<li><a href=\"#{}\">{}</a></li>\n",
                        html_escape(id),
                        html_escape(t)
                    ));
                }
                out.push_str("</ul></nav>\n");
            }
            Block::Para(t) => out.push_str(&format!("<p>{}</p>\n", html_escape(t))),
            Block::Warning(t) => out.push_str(&format!(
                "<p class=\"warning\"><strong>Warning:</strong> {}</p>\n",
                html_escape(t)
            )),
            Block::List(items) => {
                out.push_str("<ul>\n");
                for i in items {
                    out.push_str(&format!("<li>{}</li>\n", html_escape(i)));
                }
                out.push_str("</ul>\n");
            }
            Block::Table { header, rows } => {
                out.push_str("<div class=\"scroll\"><table>\n<thead><tr>");
                for h in header {
                    out.push_str(&format!("<th>{}</th>", html_escape(h)));
                }
                out.push_str("</tr></thead>\n<tbody>\n");
                for r in rows {
                    out.push_str("<tr>");
                    for c in r {
                        // Settings (`segments=40;dt=0.001`) may break after each `;`.
                        let t = c.text.split(';').map(html_escape).collect::<Vec<_>>().join(";<wbr>");
                        let t = match &c.link {
                            Some(href) => format!("<a href=\"{}\">{t}</a>", html_escape(href)),
                            None => t,
                        };
                        let t = if c.bold { format!("<strong>{t}</strong>") } else { t };
                        if c.warn {
                            out.push_str(&format!("<td class=\"warn\">{t}</td>"));
                        } else {
                            out.push_str(&format!("<td>{t}</td>"));
                        }
                    }
                    out.push_str("</tr>\n");
                }
                out.push_str("</tbody>\n</table></div>\n");
            }
            Block::Image { svg, png, alt } => {
                out.push_str(&format!(
                    "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{} (<a href=\"{}\">PNG</a>)</figcaption></figure>\n",
                    html_escape(svg),
                    html_escape(alt),
                    html_escape(alt),
                    html_escape(png)
                ));
            }
        }
    }
    out.push_str("</body>\n</html>\n");
    out
}

//! Contact sheets of a sweep (`werkstatt render --set a.b=x,y --contact-sheet`): the variants'
//! images in a grid, each with its parameter values written under it in an 8x8 bitmap font.

use image::{Rgba, RgbaImage};

/// One picture of the sheet and the lines written under it.
pub struct Cell {
    pub image: RgbaImage,
    pub label: Vec<String>,
}

const GLYPH: u32 = 8;
const PAD: u32 = 6;
const BACKGROUND: Rgba<u8> = Rgba([40, 40, 40, 255]);
const INK: Rgba<u8> = Rgba([235, 235, 235, 255]);

/// The cells in rows of `columns`, each image over its label; images smaller than the largest
/// are centred in their cell. Labels wrap at the cell's width.
pub fn montage(cells: &[Cell], columns: usize) -> RgbaImage {
    let columns = columns.clamp(1, cells.len().max(1)) as u32;
    let rows = (cells.len() as u32).div_ceil(columns);
    let image_w = cells.iter().map(|c| c.image.width()).max().unwrap_or(0).max(GLYPH * 12);
    let image_h = cells.iter().map(|c| c.image.height()).max().unwrap_or(0);
    let chars = (image_w / GLYPH) as usize;
    let wrapped: Vec<Vec<String>> = cells.iter().map(|c| wrap(&c.label, chars)).collect();
    let label_h = wrapped.iter().map(Vec::len).max().unwrap_or(0) as u32 * (GLYPH + 2);
    let (cell_w, cell_h) = (image_w + PAD, image_h + PAD + label_h + PAD);
    let mut sheet = RgbaImage::from_pixel(columns * cell_w + PAD, rows * cell_h + PAD, BACKGROUND);
    for (i, (cell, lines)) in cells.iter().zip(&wrapped).enumerate() {
        let (x0, y0) = (PAD + (i as u32 % columns) * cell_w, PAD + (i as u32 / columns) * cell_h);
        let (dx, dy) = ((image_w - cell.image.width()) / 2, (image_h - cell.image.height()) / 2);
        for (x, y, p) in cell.image.enumerate_pixels() {
            // Over the background, so that transparent renders read as they would on a page.
            let a = p[3] as u32;
            let blend = |c: u8, b: u8| ((c as u32 * a + b as u32 * (255 - a)) / 255) as u8;
            let b = BACKGROUND;
            sheet.put_pixel(
                x0 + dx + x,
                y0 + dy + y,
                Rgba([blend(p[0], b[0]), blend(p[1], b[1]), blend(p[2], b[2]), 255]),
            );
        }
        for (line, text) in lines.iter().enumerate() {
            write_text(&mut sheet, x0, y0 + image_h + PAD + line as u32 * (GLYPH + 2), text);
        }
    }
    sheet
}

/// Lines of at most `chars` characters, broken after `+`, `=`, `,`, then `.`, or anywhere when a word is
/// longer than a line.
fn wrap(lines: &[String], chars: usize) -> Vec<String> {
    let chars = chars.max(1);
    let mut out = Vec::new();
    for line in lines {
        let mut rest: &str = line;
        while rest.chars().count() > chars {
            let head: String = rest.chars().take(chars).collect();
            // After an assignment's parts first; after a dot (a node's name) only failing that,
            // so that numbers stay whole.
            let cut = head.rfind(['+', '=', ',', ' ']).or_else(|| head.rfind('.')).map_or(head.len(), |i| i + 1);
            out.push(rest[..cut].to_string());
            rest = &rest[cut..];
        }
        out.push(rest.to_string());
    }
    out
}

/// Writes ASCII text with its top-left corner at (x, y); other characters print as '?', and
/// what falls off the image is clipped.
fn write_text(img: &mut RgbaImage, x: u32, y: u32, text: &str) {
    for (i, c) in text.chars().enumerate() {
        let code = if c.is_ascii() { c as usize } else { '?' as usize };
        let glyph = font8x8::legacy::BASIC_LEGACY[code];
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..GLYPH {
                // font8x8: bit 0 is the leftmost pixel of a row.
                if bits >> col & 1 == 1 {
                    let (px, py) = (x + i as u32 * GLYPH + col, y + row as u32);
                    if px < img.width() && py < img.height() {
                        img.put_pixel(px, py, INK);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_land_in_a_grid_with_their_labels_under_them() {
        let cell = |v: u8, label: &str| Cell {
            image: RgbaImage::from_pixel(96, 64, Rgba([v, v, v, 255])),
            label: vec![label.to_string()],
        };
        let cells = [cell(200, "a.b=1"), cell(100, "a.b=2"), cell(50, "a.b=3")];
        let sheet = montage(&cells, 2);
        let (cell_w, label_h) = (96 + PAD, GLYPH + 2);
        let cell_h = 64 + PAD + label_h + PAD;
        assert_eq!(sheet.dimensions(), (2 * cell_w + PAD, 2 * cell_h + PAD));
        // Each image's centre, in order, row by row.
        for (i, v) in [200u8, 100, 50].iter().enumerate() {
            let (x, y) = (PAD + (i as u32 % 2) * cell_w + 48, PAD + (i as u32 / 2) * cell_h + 32);
            assert_eq!(sheet.get_pixel(x, y)[0], *v, "cell {i}");
        }
        // Ink under the first image, none in the empty fourth cell.
        let ink = |x0: u32, y0: u32| (x0..x0 + 96).any(|x| (y0..y0 + GLYPH).any(|y| *sheet.get_pixel(x, y) == INK));
        assert!(ink(PAD, PAD + 64 + PAD));
        assert!(!ink(PAD + cell_w, cell_h + PAD + 64 + PAD));
    }

    #[test]
    fn long_labels_wrap_at_a_separator() {
        let lines = wrap(&["fabric.glossiness=0.25+light.sun_intensity=2".to_string()], 20);
        assert_eq!(lines, ["fabric.glossiness=", "0.25+", "light.sun_intensity=", "2"]);
        assert!(lines.iter().all(|l| l.len() <= 20));
    }
}

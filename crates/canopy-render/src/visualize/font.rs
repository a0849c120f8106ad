//! A 3x5 pixel font for the digits and a few signs, enough to label legends and scale
//! bars without shipping a font file.

/// Rows of a glyph, top first; bit 2 is the left column.
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b010, 0b010, 0b010],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        '.' => [0b000, 0b000, 0b000, 0b000, 0b010],
        '-' => [0b000, 0b000, 0b111, 0b000, 0b000],
        ' ' => [0; 5],
        _ => return None,
    })
}

/// Width in pixels of `text` drawn at `scale`.
pub fn text_width(text: &str, scale: u32) -> u32 {
    (text.chars().count() as u32 * 4).saturating_sub(1) * scale
}

/// Calls `plot(x, y)` for every lit pixel of `text` with its top-left corner at (x, y).
/// Characters without a glyph are drawn as blanks.
pub fn draw_text(text: &str, x: i32, y: i32, scale: u32, mut plot: impl FnMut(i32, i32)) {
    let s = scale as i32;
    for (i, c) in text.chars().enumerate() {
        let Some(rows) = glyph(c) else { continue };
        let gx = x + i as i32 * 4 * s;
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) != 0 {
                    for dy in 0..s {
                        for dx in 0..s {
                            plot(gx + col * s + dx, y + row as i32 * s + dy);
                        }
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
    fn one_is_drawn_with_its_eight_pixels() {
        let mut lit = Vec::new();
        draw_text("1", 0, 0, 1, |x, y| lit.push((x, y)));
        assert_eq!(lit.len(), 8);
        assert!(lit.contains(&(1, 0)) && lit.contains(&(0, 4)) && lit.contains(&(2, 4)));
        assert_eq!(text_width("10", 2), 14);
    }
}

//! A rectangle of the image, in pixels: what one render job (or one task of a distributed
//! render) draws. A pixel's samples do not depend on the region it is rendered in, so the
//! regions of a split image put together give the whole image bit for bit.

use std::fmt;
use std::str::FromStr;

/// Pixels `x .. x + width` of rows `y .. y + height`; (0, 0) is the top-left pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Region {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Region {
    /// The whole of a `width` x `height` image.
    pub fn full(width: u32, height: u32) -> Self {
        Self {
            x: 0,
            y: 0,
            width,
            height,
        }
    }

    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether the region is a non-empty part of a `width` x `height` image, or what
    /// is wrong with it.
    pub fn check_within(&self, width: u32, height: u32) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!("the region {self} has no pixels"));
        }
        let right = self.x as u64 + self.width as u64;
        let bottom = self.y as u64 + self.height as u64;
        if right > width as u64 || bottom > height as u64 {
            return Err(format!(
                "the region {self} reaches beyond the {width}x{height} image"
            ));
        }
        Ok(())
    }

    /// Whether this is the whole of a `width` x `height` image.
    pub fn is_full(&self, width: u32, height: u32) -> bool {
        *self == Self::full(width, height)
    }

    /// Splits the region into tiles of at most `tile` x `tile` pixels, row by row.
    pub fn tiles(&self, tile: u32) -> Vec<Region> {
        let tile = tile.max(1);
        let mut out = Vec::new();
        for y in (self.y..self.y + self.height).step_by(tile as usize) {
            for x in (self.x..self.x + self.width).step_by(tile as usize) {
                out.push(Region {
                    x,
                    y,
                    width: tile.min(self.x + self.width - x),
                    height: tile.min(self.y + self.height - y),
                });
            }
        }
        out
    }
}

/// As `X,Y,WIDTHxHEIGHT`, the form [`Region::from_str`] reads.
impl fmt::Display for Region {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{}x{}", self.x, self.y, self.width, self.height)
    }
}

impl FromStr for Region {
    type Err = String;

    /// `X,Y,WIDTHxHEIGHT`, e.g. `0,120,640x60`.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad =
            || format!("{s:?} is not a region: expected X,Y,WIDTHxHEIGHT (e.g. 0,120,640x60)");
        let mut parts = s.split(',');
        let (Some(x), Some(y), Some(size), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return Err(bad());
        };
        let (w, h) = size.split_once(['x', 'X']).ok_or_else(bad)?;
        let number = |t: &str| t.trim().parse::<u32>().map_err(|_| bad());
        Ok(Region {
            x: number(x)?,
            y: number(y)?,
            width: number(w)?,
            height: number(h)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_what_it_prints_and_refuses_the_rest() {
        let r: Region = "3,4,20x10".parse().unwrap();
        assert_eq!(
            r,
            Region {
                x: 3,
                y: 4,
                width: 20,
                height: 10
            }
        );
        assert_eq!(r.to_string().parse::<Region>().unwrap(), r);
        for bad in [
            "",
            "1,2",
            "1,2,3",
            "1,2,3x",
            "a,2,3x4",
            "1,2,3x4,5",
            "-1,0,2x2",
        ] {
            assert!(bad.parse::<Region>().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn checks_that_it_lies_within_the_image() {
        let image = (100, 50);
        assert!(Region::full(100, 50).check_within(image.0, image.1).is_ok());
        let edge = Region {
            x: 90,
            y: 40,
            width: 10,
            height: 10,
        };
        assert!(edge.check_within(image.0, image.1).is_ok());
        let over = Region { x: 91, ..edge };
        assert!(over
            .check_within(image.0, image.1)
            .unwrap_err()
            .contains("beyond"));
        let empty = Region { width: 0, ..edge };
        assert!(empty
            .check_within(image.0, image.1)
            .unwrap_err()
            .contains("no pixels"));
        let huge = Region {
            x: u32::MAX,
            y: 0,
            width: 2,
            height: 1,
        };
        assert!(huge.check_within(image.0, image.1).is_err());
    }

    #[test]
    fn tiles_cover_the_region_once() {
        let r = Region {
            x: 5,
            y: 7,
            width: 23,
            height: 11,
        };
        let tiles = r.tiles(8);
        assert_eq!(tiles.len(), 3 * 2);
        let mut covered = vec![0u8; 64 * 64];
        for t in &tiles {
            t.check_within(r.x + r.width, r.y + r.height).unwrap();
            for y in t.y..t.y + t.height {
                for x in t.x..t.x + t.width {
                    covered[(y * 64 + x) as usize] += 1;
                }
            }
        }
        let inside = |i: usize| {
            let (x, y) = ((i % 64) as u32, (i / 64) as u32);
            x >= r.x && x < r.x + r.width && y >= r.y && y < r.y + r.height
        };
        for (i, &n) in covered.iter().enumerate() {
            assert_eq!(n, inside(i) as u8, "pixel {i}");
        }
    }
}

//! State per pixel (or per region of pixels), for any address a 16-bit event can carry.
//!
//! An event file need not say how large its sensor is, and a stray address (65535, 65535) must
//! not make the filters allocate a 65536 x 65536 array. The map is paged: 64 x 64 cells a page,
//! allocated when an address in it first comes; the page table grows with the largest address
//! seen (at most 1024 x 1024 page pointers, 8 MB, for the whole 16-bit range).

const PAGE_BITS: u32 = 6;
const PAGE_SIDE: usize = 1 << PAGE_BITS;
const PAGE_MASK: usize = PAGE_SIDE - 1;
/// Pages along a side for the whole 16-bit address range.
const MAX_SIDE_PAGES: usize = (u16::MAX as usize + 1) >> PAGE_BITS;

pub(crate) struct PixelMap<T> {
    /// Page table: `columns` pages a row, row-major; None until a cell of the page is used.
    pages: Vec<Option<Box<[T]>>>,
    columns: usize,
    rows: usize,
}

impl<T: Copy + Default> PixelMap<T> {
    /// A map whose page table already covers `width` x `height` cells (0 x 0 is fine: it grows;
    /// more than the 16-bit range is taken as all of it).
    pub(crate) fn new(width: usize, height: usize) -> Self {
        let columns = width.div_ceil(PAGE_SIDE).min(MAX_SIDE_PAGES);
        let rows = height.div_ceil(PAGE_SIDE).min(MAX_SIDE_PAGES);
        Self {
            pages: (0..columns * rows).map(|_| None).collect(),
            columns,
            rows,
        }
    }

    /// The state of cell (x, y), default until first written.
    #[inline]
    pub(crate) fn get_mut(&mut self, x: u16, y: u16) -> &mut T {
        let (x, y) = (usize::from(x), usize::from(y));
        let (column, row) = (x >> PAGE_BITS, y >> PAGE_BITS);
        if column >= self.columns || row >= self.rows {
            self.grow(column + 1, row + 1);
        }
        let page = self.pages[row * self.columns + column]
            .get_or_insert_with(|| vec![T::default(); PAGE_SIDE * PAGE_SIDE].into_boxed_slice());
        &mut page[((y & PAGE_MASK) << PAGE_BITS) | (x & PAGE_MASK)]
    }

    /// Widens the page table to at least `columns` x `rows` pages, keeping every page where it
    /// is on the sensor. A side that must grow at least doubles, so that a stream whose addresses
    /// creep up re-lays the table out rarely.
    fn grow(&mut self, columns: usize, rows: usize) {
        let widened = |old: usize, needed: usize| {
            if needed <= old {
                old
            } else {
                needed.max((old * 2).min(MAX_SIDE_PAGES))
            }
        };
        let new_columns = widened(self.columns, columns);
        let new_rows = widened(self.rows, rows);
        let mut pages: Vec<Option<Box<[T]>>> = (0..new_columns * new_rows).map(|_| None).collect();
        for (index, page) in self.pages.drain(..).enumerate() {
            let (row, column) = (index / self.columns, index % self.columns);
            pages[row * new_columns + column] = page;
        }
        self.pages = pages;
        self.columns = new_columns;
        self.rows = new_rows;
    }
}

#[cfg(test)]
mod tests {
    use super::PixelMap;

    #[test]
    fn cells_keep_their_values_when_the_map_grows() {
        let mut map = PixelMap::<u32>::new(0, 0);
        *map.get_mut(3, 5) = 7;
        *map.get_mut(200, 1) = 8; // grows the columns
        *map.get_mut(2, 300) = 9; // grows the rows
        *map.get_mut(65535, 65535) = 10; // the last address a u16 holds
        assert_eq!(*map.get_mut(3, 5), 7);
        assert_eq!(*map.get_mut(200, 1), 8);
        assert_eq!(*map.get_mut(2, 300), 9);
        assert_eq!(*map.get_mut(65535, 65535), 10);
        assert_eq!(*map.get_mut(4, 5), 0);
    }

    #[test]
    fn a_size_hint_past_the_address_range_is_capped() {
        let mut map = PixelMap::<u8>::new(usize::MAX, usize::MAX);
        *map.get_mut(65535, 0) = 1;
        assert_eq!(*map.get_mut(65535, 0), 1);
    }
}

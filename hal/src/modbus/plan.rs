//! Transaction planning: the fewest read requests that cover a device's points.
//!
//! Points of the same table are sorted by address and merged into one request while the
//! request stays within the protocol's size limit and the gap between points is at most
//! `max_gap` items (reading a few unused registers is cheaper than another round trip, but
//! some devices answer an exception for addresses they do not have, so the default gap is 0:
//! only adjacent or overlapping points merge).

use super::map::{PointSpec, Table};

/// One read request and the points it serves.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadBlock {
    /// Table read.
    pub table: Table,
    /// First address.
    pub start: u16,
    /// Items read.
    pub count: u16,
    /// `(point index, offset of the point in the block)`.
    pub points: Vec<(usize, u16)>,
}

impl ReadBlock {
    /// The raw items of point at `offset` within `data` (the block's response).
    pub fn slice<'a>(&self, data: &'a [u16], offset: u16) -> &'a [u16] {
        data.get(usize::from(offset)..).unwrap_or(&[])
    }
}

/// Plans the reads for `points` (index = point index). Points not to be read are `None`.
pub fn plan_reads(points: &[Option<PointSpec>], max_gap: u16) -> Vec<ReadBlock> {
    let mut sorted: Vec<(usize, PointSpec)> = points
        .iter()
        .enumerate()
        .filter_map(|(i, p)| p.map(|p| (i, p)))
        .collect();
    sorted.sort_by_key(|(i, p)| (p.table, p.address, *i));
    let mut blocks: Vec<ReadBlock> = Vec::new();
    for (i, p) in sorted {
        let end = u32::from(p.address) + u32::from(p.width());
        if let Some(b) = blocks.last_mut() {
            let b_end = u32::from(b.start) + u32::from(b.count);
            let near = u32::from(p.address) <= b_end + u32::from(max_gap);
            let new_count = end.max(b_end) - u32::from(b.start);
            if b.table == p.table && near && new_count <= u32::from(p.table.max_read()) {
                b.count = new_count as u16;
                b.points.push((i, p.address - b.start));
                continue;
            }
        }
        blocks.push(ReadBlock {
            table: p.table,
            start: p.address,
            count: p.width(),
            points: vec![(i, 0)],
        });
    }
    blocks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modbus::map::{DataType, WordOrder};

    fn pt(table: Table, address: u16, t: DataType) -> Option<PointSpec> {
        Some(PointSpec::new(table, address, t, WordOrder::HighFirst).unwrap())
    }

    #[test]
    fn adjacent_points_of_one_table_share_a_request() {
        let points = [
            pt(Table::DiscreteInput, 2, DataType::Bool),
            pt(Table::DiscreteInput, 0, DataType::Bool),
            pt(Table::DiscreteInput, 1, DataType::Bool),
            pt(Table::InputRegister, 0, DataType::F32),
            pt(Table::InputRegister, 2, DataType::U16),
            pt(Table::InputRegister, 2, DataType::Bit(4)),
            pt(Table::InputRegister, 10, DataType::U16),
            None,
        ];
        let blocks = plan_reads(&points, 0);
        assert_eq!(blocks.len(), 3, "{blocks:?}");
        assert_eq!(
            blocks[0],
            ReadBlock {
                table: Table::DiscreteInput,
                start: 0,
                count: 3,
                points: vec![(1, 0), (2, 1), (0, 2)],
            }
        );
        assert_eq!(blocks[1].start, 0);
        assert_eq!(blocks[1].count, 3);
        assert_eq!(blocks[1].points, vec![(3, 0), (4, 2), (5, 2)]);
        assert_eq!((blocks[2].start, blocks[2].count), (10, 1));
        // With a gap allowance, the far register joins the block.
        let merged = plan_reads(&points, 8);
        assert_eq!(merged.len(), 2);
        assert_eq!(merged[1].count, 11);
    }

    #[test]
    fn requests_stay_within_the_protocol_limit() {
        let points: Vec<_> = (0..300)
            .map(|a| pt(Table::HoldingRegister, a, DataType::U16))
            .collect();
        let blocks = plan_reads(&points, 0);
        let counts: Vec<u16> = blocks.iter().map(|b| b.count).collect();
        assert_eq!(counts, [125, 125, 50]);
        // A 32-bit value is never split across requests.
        let mut pts: Vec<_> = (0..124)
            .map(|a| pt(Table::HoldingRegister, a, DataType::U16))
            .collect();
        pts.push(pt(Table::HoldingRegister, 124, DataType::U32));
        let blocks = plan_reads(&pts, 0);
        assert_eq!(blocks.len(), 2);
        assert_eq!((blocks[1].start, blocks[1].count), (124, 2));
    }
}

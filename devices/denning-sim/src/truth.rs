//! The simulator's ground truth: where the robot really is, one record per status period,
//! written as CSV (`--trajectory FILE`) and read back by name, so a reader (the exit-lab
//! demo, a test) depends on this type rather than on column positions.

use std::io::{self, Write};
use std::path::Path;

/// One ground-truth record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthRecord {
    /// Simulated time (s).
    pub t: f64,
    /// Position (m).
    pub x: f64,
    /// Position (m).
    pub y: f64,
    /// Heading (rad).
    pub theta: f64,
    /// Translate velocity (m/s).
    pub v: f64,
    /// Rotate velocity (rad/s).
    pub w: f64,
    /// Whether the drive is stalled.
    pub stall: bool,
    /// Collisions so far.
    pub collisions: u64,
    /// Whether the robot is in the world's outside region.
    pub outside: bool,
    /// Simulated seconds since the last drive command (VEL or RVEL) reached the robot.
    pub cmd_age: f64,
    /// Whether a non-zero drive command is in force (the robot is being driven, not stopping).
    pub driven: bool,
    /// The robot's floor (0 in a plain world; riding between floors, the one it left).
    pub floor: i32,
    /// Messages spoken so far.
    pub said: u32,
    /// Whether the message has been delivered (spoken at the building's goal).
    pub delivered: bool,
    /// Whether the robot is back at the lab: near the point in front of its door, on its floor
    /// (`Building::lab_goal`). Read as false from a file written before the column was.
    pub at_lab: bool,
}

impl TruthRecord {
    /// The CSV header: the column names [`TruthRecord::read`] looks columns up by.
    pub const HEADER: &'static str =
        "t,x,y,theta,v,w,stall,collisions,outside,cmd_age,driven,floor,said,delivered,at_lab";

    /// Writes the record as one CSV line.
    pub fn write(&self, out: &mut impl Write) -> io::Result<()> {
        writeln!(
            out,
            "{:.3},{:.4},{:.4},{:.4},{:.3},{:.3},{},{},{},{:.3},{},{},{},{},{}",
            self.t,
            self.x,
            self.y,
            self.theta,
            self.v,
            self.w,
            u8::from(self.stall),
            self.collisions,
            u8::from(self.outside),
            self.cmd_age,
            u8::from(self.driven),
            self.floor,
            self.said,
            u8::from(self.delivered),
            u8::from(self.at_lab)
        )
    }

    /// Every complete record of a ground-truth file (a line being written is skipped).
    pub fn read(path: &Path) -> io::Result<Vec<TruthRecord>> {
        Ok(Self::parse_all(&std::fs::read_to_string(path)?))
    }

    /// Every complete record of ground-truth CSV text, columns found by their header names.
    pub fn parse_all(text: &str) -> Vec<TruthRecord> {
        let mut lines = text.lines();
        let Some(header) = lines.next() else {
            return Vec::new();
        };
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let col = |name: &str| names.iter().position(|n| *n == name);
        // Every column but the newest, `at_lab`, must be there.
        let (required, _) = Self::HEADER.rsplit_once(',').unwrap_or((Self::HEADER, ""));
        let cols: Option<Vec<usize>> = required.split(',').map(col).collect();
        let Some(cols) = cols else {
            return Vec::new();
        };
        let at_lab = col("at_lab");
        lines
            .filter_map(|line| {
                let f: Vec<f64> = line
                    .split(',')
                    .map(|x| x.trim().parse().ok())
                    .collect::<Option<_>>()?;
                let at = |i: usize| f.get(cols[i]).copied();
                Some(TruthRecord {
                    t: at(0)?,
                    x: at(1)?,
                    y: at(2)?,
                    theta: at(3)?,
                    v: at(4)?,
                    w: at(5)?,
                    stall: at(6)? > 0.5,
                    collisions: at(7)? as u64,
                    outside: at(8)? > 0.5,
                    cmd_age: at(9)?,
                    driven: at(10)? > 0.5,
                    floor: at(11)? as i32,
                    said: at(12)? as u32,
                    delivered: at(13)? > 0.5,
                    at_lab: match at_lab {
                        Some(i) => *f.get(i)? > 0.5,
                        None => false,
                    },
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_through_csv_and_a_cut_line_is_skipped() {
        let r = TruthRecord {
            t: 12.5,
            x: 3.25,
            y: -1.5,
            theta: 0.5,
            v: 0.3,
            w: -0.2,
            stall: false,
            collisions: 2,
            outside: true,
            cmd_age: 0.1,
            driven: true,
            floor: -1,
            said: 3,
            delivered: true,
            at_lab: true,
        };
        let mut text = format!("{}\n", TruthRecord::HEADER).into_bytes();
        r.write(&mut text).unwrap();
        text.extend_from_slice(b"13.0,3.3");
        let all = TruthRecord::parse_all(std::str::from_utf8(&text).unwrap());
        assert_eq!(all, vec![r]);
    }

    #[test]
    fn columns_are_found_by_name() {
        let text = "delivered,said,floor,driven,cmd_age,outside,collisions,stall,w,v,theta,y,x,t\n\
                    1,2,4,1,0.1,1,0,0,0,0,0,2,1,5\n";
        let all = TruthRecord::parse_all(text);
        assert_eq!(all.len(), 1);
        assert_eq!(
            (all[0].t, all[0].x, all[0].y, all[0].outside),
            (5.0, 1.0, 2.0, true)
        );
        assert_eq!((all[0].floor, all[0].said, all[0].delivered), (4, 2, true));
        assert!(TruthRecord::parse_all("a,b\n1,2\n").is_empty());
    }
}

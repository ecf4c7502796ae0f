//! One measured test point: the row of every sweep CSV the rig tools write and read.
//!
//! `rig sim torque-sweep --csv` (the simulator's sweep), `rig experiment torque-sweep --csv`
//! and `rig discover` (the procedure's, with provenance), and `rig explain --save-data`
//! (explain's standard columns) each write [`MeasuredRow`]s under their own [`Format`]: the
//! columns they carry, in their order, with their number style. Each column has one name
//! ([`Column::name`], the serde name of its field as well); a column a writer lacks is a
//! `None` field, written as an empty cell where the format has the column.
//!
//! `rig explain` reads any of them (its own streaming reader, `explain::Dataset`); the
//! procedure reads its rows back for `--resume` with serde under the same names.

use std::borrow::Borrow;

use serde::{Deserialize, Serialize};

/// One test point: the drive, the load, what was measured and, where the writer knows
/// them, the estimates beside it. Field names are the physics'; the CSV and JSON names are
/// the columns' ([`Column::name`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MeasuredRow {
    /// Position in the plan's run order (the procedure's `--resume` skips those written).
    pub point: Option<usize>,
    /// Repeat, 0-based.
    pub repeat: Option<u32>,
    /// Time of the test since the start of the session (the averaging window's start), s.
    pub t_s: Option<f64>,
    /// Vibrator supply voltage in open loop, V (`None` in closed loop).
    #[serde(rename = "v_in_v")]
    pub v_in: Option<f64>,
    /// Closed-loop target frequency, Hz (`None` in open loop).
    pub target_hz: Option<f64>,
    /// Cam speed w_n, mean over the window, rad/s.
    #[serde(rename = "omega_n_rad_s")]
    pub omega_n: f64,
    /// Load torque on the output tau_rot, N m.
    #[serde(rename = "tau_rot_nm")]
    pub tau_rot: f64,
    /// Mean vibrator current over the window, A (`None` only where the load was not
    /// backdriven: the paper has no current there).
    #[serde(rename = "i_in_a")]
    pub i_in: Option<f64>,
    /// Motor temperature at the window's start, deg C (`None` when not sensed).
    pub temp_c: Option<f64>,
    /// The firmware's tau_cam estimate, mean over the window, N m.
    #[serde(rename = "tau_cam_est_nm")]
    pub tau_cam_est: Option<f64>,
    /// tau_cam from the mean current by Eqs. (15)-(17), N m (the simulator's sweep).
    #[serde(rename = "tau_cam_meas_nm")]
    pub tau_cam_meas: Option<f64>,
    /// Eq. (10) at the mean cam speed, N m (the simulator's sweep).
    #[serde(rename = "tau_cam_eq10_nm")]
    pub tau_cam_eq10: Option<f64>,
    /// Whether the output backdrove (1) or held (0); `None` when nobody could tell.
    #[serde(default, with = "flag")]
    pub backdriven: Option<bool>,
    /// The load as the mass hung on the paper's output pulley, kg.
    pub load_kg: Option<f64>,
}

/// A column of a sweep CSV: one field of [`MeasuredRow`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Column {
    /// `point`: [`MeasuredRow::point`].
    Point,
    /// `repeat`: [`MeasuredRow::repeat`].
    Repeat,
    /// `t_s`: [`MeasuredRow::t_s`].
    Time,
    /// `v_in_v`: [`MeasuredRow::v_in`].
    Supply,
    /// `target_hz`: [`MeasuredRow::target_hz`].
    TargetHz,
    /// `omega_n_rad_s`: [`MeasuredRow::omega_n`].
    CamSpeed,
    /// `tau_rot_nm`: [`MeasuredRow::tau_rot`].
    Load,
    /// `i_in_a`: [`MeasuredRow::i_in`].
    Current,
    /// `temp_c`: [`MeasuredRow::temp_c`].
    Temperature,
    /// `tau_cam_est_nm`: [`MeasuredRow::tau_cam_est`].
    TauCamEstimate,
    /// `tau_cam_meas_nm`: [`MeasuredRow::tau_cam_meas`].
    TauCamMeasured,
    /// `tau_cam_eq10_nm`: [`MeasuredRow::tau_cam_eq10`].
    TauCamEq10,
    /// `backdriven`: [`MeasuredRow::backdriven`], 1 or 0.
    Backdriven,
    /// `load_kg`: [`MeasuredRow::load_kg`].
    LoadKg,
}

/// A cell's value before it is written.
enum Cell {
    Number(Option<f64>),
    Count(Option<u64>),
    Flag(Option<bool>),
}

impl Column {
    /// Every column, one per field of [`MeasuredRow`], in the field order.
    pub const ALL: [Column; 14] = [
        Column::Point,
        Column::Repeat,
        Column::Time,
        Column::Supply,
        Column::TargetHz,
        Column::CamSpeed,
        Column::Load,
        Column::Current,
        Column::Temperature,
        Column::TauCamEstimate,
        Column::TauCamMeasured,
        Column::TauCamEq10,
        Column::Backdriven,
        Column::LoadKg,
    ];

    /// The column's name in a CSV header (and the field's serde name).
    pub const fn name(self) -> &'static str {
        match self {
            Column::Point => "point",
            Column::Repeat => "repeat",
            Column::Time => "t_s",
            Column::Supply => "v_in_v",
            Column::TargetHz => "target_hz",
            Column::CamSpeed => "omega_n_rad_s",
            Column::Load => "tau_rot_nm",
            Column::Current => "i_in_a",
            Column::Temperature => "temp_c",
            Column::TauCamEstimate => "tau_cam_est_nm",
            Column::TauCamMeasured => "tau_cam_meas_nm",
            Column::TauCamEq10 => "tau_cam_eq10_nm",
            Column::Backdriven => "backdriven",
            Column::LoadKg => "load_kg",
        }
    }

    fn cell(self, r: &MeasuredRow) -> Cell {
        match self {
            Column::Point => Cell::Count(r.point.map(|p| p as u64)),
            Column::Repeat => Cell::Count(r.repeat.map(u64::from)),
            Column::Time => Cell::Number(r.t_s),
            Column::Supply => Cell::Number(r.v_in),
            Column::TargetHz => Cell::Number(r.target_hz),
            Column::CamSpeed => Cell::Number(Some(r.omega_n)),
            Column::Load => Cell::Number(Some(r.tau_rot)),
            Column::Current => Cell::Number(r.i_in),
            Column::Temperature => Cell::Number(r.temp_c),
            Column::TauCamEstimate => Cell::Number(r.tau_cam_est),
            Column::TauCamMeasured => Cell::Number(r.tau_cam_meas),
            Column::TauCamEq10 => Cell::Number(r.tau_cam_eq10),
            Column::Backdriven => Cell::Flag(r.backdriven),
            Column::LoadKg => Cell::Number(r.load_kg),
        }
    }

    /// Whether `row` has a value in this column.
    pub fn is_present(self, row: &MeasuredRow) -> bool {
        match self.cell(row) {
            Cell::Number(v) => v.is_some(),
            Cell::Count(v) => v.is_some(),
            Cell::Flag(v) => v.is_some(),
        }
    }
}

/// How a format writes its numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Numbers {
    /// The shortest text that reads back to the same `f64`, as serde's CSV writer gives
    /// it: `5.0`, `0.368`, `1e-7`.
    Shortest,
    /// Rust's `Display`: `5`, `0.368`, `0.0000001`.
    Plain,
}

/// A sweep CSV's layout: its columns in order, the ones a completed row has, and its
/// number style. A row's `None` is an empty cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Format {
    /// The columns, in order.
    pub columns: &'static [Column],
    /// The columns every completed row has (a row without one was cut short by a crash).
    pub required: &'static [Column],
    /// How numbers are written.
    pub numbers: Numbers,
}

/// `rig sim torque-sweep --csv` and `rig demo`'s `torque_sweep.csv`: the simulator's sweep
/// with the torques it knows besides the current.
pub const SIM_SWEEP: Format = Format {
    columns: &[
        Column::Time,
        Column::Supply,
        Column::CamSpeed,
        Column::Load,
        Column::Current,
        Column::Temperature,
        Column::Repeat,
        Column::TauCamEstimate,
        Column::TauCamMeasured,
        Column::TauCamEq10,
        Column::Backdriven,
    ],
    required: &[Column::CamSpeed, Column::Load, Column::Current],
    numbers: Numbers::Shortest,
};

/// `rig experiment torque-sweep --csv` and `rig discover --csv` (after their provenance):
/// the procedure's rows on any rig. `load_kg` came last, later: older files lack it.
pub const EXPERIMENT_SWEEP: Format = Format {
    columns: &[
        Column::Point,
        Column::Repeat,
        Column::Time,
        Column::Supply,
        Column::TargetHz,
        Column::CamSpeed,
        Column::Load,
        Column::Current,
        Column::Temperature,
        Column::TauCamEstimate,
        Column::Backdriven,
        Column::LoadKg,
    ],
    required: &[
        Column::Point,
        Column::Repeat,
        Column::Time,
        Column::CamSpeed,
        Column::Load,
        Column::Current,
        Column::TauCamEstimate,
    ],
    numbers: Numbers::Shortest,
};

/// The columns `rig explain` reads: required first, then the optional ones in this order.
pub const EXPLAIN_COLUMNS: [Column; 7] = [
    Column::CamSpeed,
    Column::Load,
    Column::Current,
    Column::Time,
    Column::Supply,
    Column::Temperature,
    Column::Backdriven,
];

impl Format {
    /// The header line, with its line end.
    pub fn header(&self) -> String {
        let names: Vec<&str> = self.columns.iter().map(|c| c.name()).collect();
        names.join(",") + "\n"
    }

    /// Whether `row` has every column a completed row has.
    pub fn is_complete(&self, row: &MeasuredRow) -> bool {
        self.required.iter().all(|c| c.is_present(row))
    }

    /// Writes `rows` as CSV to `out`, the header first when `header` and there is a row.
    pub fn write_csv<W: std::io::Write, R: Borrow<MeasuredRow>>(
        &self,
        out: W,
        header: bool,
        rows: impl IntoIterator<Item = R>,
    ) -> Result<(), csv::Error> {
        write_columns(out, self.columns, self.numbers, header, rows)
    }
}

/// Writes `rows` as CSV under `columns` (see [`Format::write_csv`]); for a writer whose
/// columns depend on the data (explain's, which leaves out absent optional columns).
pub fn write_columns<W: std::io::Write, R: Borrow<MeasuredRow>>(
    out: W,
    columns: &[Column],
    numbers: Numbers,
    header: bool,
    rows: impl IntoIterator<Item = R>,
) -> Result<(), csv::Error> {
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(out);
    let mut first = true;
    let mut buffer = ryu::Buffer::new();
    let mut record = csv::ByteRecord::with_capacity(128, columns.len());
    for row in rows {
        if std::mem::take(&mut first) && header {
            w.write_record(columns.iter().map(|c| c.name()))?;
        }
        record.clear();
        for column in columns {
            match column.cell(row.borrow()) {
                Cell::Number(None) | Cell::Count(None) | Cell::Flag(None) => record.push_field(b""),
                Cell::Number(Some(v)) => match numbers {
                    Numbers::Shortest => record.push_field(buffer.format(v).as_bytes()),
                    Numbers::Plain => record.push_field(format!("{v}").as_bytes()),
                },
                Cell::Count(Some(n)) => record.push_field(n.to_string().as_bytes()),
                Cell::Flag(Some(b)) => record.push_field(if b { b"1" } else { b"0" }),
            }
        }
        w.write_byte_record(&record)?;
    }
    w.flush()?;
    Ok(())
}

/// `backdriven` as 1 or 0 (serde's `with`); reads 1/0, true/false and yes/no.
mod flag {
    use serde::de::{self, Deserializer, Visitor};
    use serde::ser::Serializer;

    /// 1, 0 or none.
    pub fn serialize<S: Serializer>(v: &Option<bool>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(b) => s.serialize_some(&u8::from(*b)),
            None => s.serialize_none(),
        }
    }

    /// An empty cell or a null is none.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<bool>, D::Error> {
        d.deserialize_option(Optional)
    }

    struct Optional;
    struct Flag;

    impl<'de> Visitor<'de> for Optional {
        type Value = Option<bool>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("1 (backdriven), 0 (held) or nothing")
        }
        fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_some<D: de::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
            d.deserialize_any(Flag).map(Some)
        }
    }

    impl Visitor<'_> for Flag {
        type Value = bool;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("1 (backdriven) or 0 (held)")
        }
        fn visit_bool<E: de::Error>(self, v: bool) -> Result<bool, E> {
            Ok(v)
        }
        fn visit_u64<E: de::Error>(self, v: u64) -> Result<bool, E> {
            match v {
                0 => Ok(false),
                1 => Ok(true),
                _ => Err(E::invalid_value(de::Unexpected::Unsigned(v), &self)),
            }
        }
        fn visit_i64<E: de::Error>(self, v: i64) -> Result<bool, E> {
            match u64::try_from(v) {
                Ok(v) => self.visit_u64(v),
                Err(_) => Err(E::invalid_value(de::Unexpected::Signed(v), &self)),
            }
        }
        fn visit_str<E: de::Error>(self, v: &str) -> Result<bool, E> {
            let v = v.trim();
            if ["1", "true", "yes"]
                .iter()
                .any(|t| v.eq_ignore_ascii_case(t))
            {
                Ok(true)
            } else if ["0", "false", "no"]
                .iter()
                .any(|t| v.eq_ignore_ascii_case(t))
            {
                Ok(false)
            } else {
                Err(E::invalid_value(de::Unexpected::Str(v), &self))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row() -> MeasuredRow {
        MeasuredRow {
            point: Some(3),
            repeat: Some(1),
            t_s: Some(1.5),
            v_in: Some(3.6),
            omega_n: 31.4,
            tau_rot: 0.368,
            i_in: Some(2.5),
            tau_cam_est: Some(1e-7),
            backdriven: Some(false),
            ..MeasuredRow::default()
        }
    }

    fn text(f: &Format, rows: &[MeasuredRow]) -> String {
        let mut out = Vec::new();
        f.write_csv(&mut out, true, rows).unwrap();
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn each_format_writes_its_columns_in_order_with_empty_cells_for_none() {
        assert_eq!(
            text(&EXPERIMENT_SWEEP, &[row()]),
            EXPERIMENT_SWEEP.header() + "3,1,1.5,3.6,,31.4,0.368,2.5,,1e-7,0,\n"
        );
        assert_eq!(
            text(&SIM_SWEEP, &[row()]),
            SIM_SWEEP.header() + "1.5,3.6,31.4,0.368,2.5,,1,1e-7,,,0\n"
        );
        // No rows: not even a header.
        assert_eq!(text(&SIM_SWEEP, &[]), "");
        let mut out = Vec::new();
        write_columns(&mut out, &EXPLAIN_COLUMNS, Numbers::Plain, false, [row()]).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "31.4,0.368,2.5,1.5,3.6,,0\n"
        );
    }

    #[test]
    fn every_field_is_a_column_under_its_serde_name() {
        // The columns' names are the fields' serde names: a row written under every
        // column reads back whole through serde.
        let all = Column::ALL;
        let full = MeasuredRow {
            target_hz: Some(5.0),
            temp_c: Some(25.5),
            tau_cam_meas: Some(0.02),
            tau_cam_eq10: Some(0.03),
            load_kg: Some(0.5),
            backdriven: Some(true),
            ..row()
        };
        let mut out = Vec::new();
        write_columns(&mut out, &all, Numbers::Shortest, true, [full]).unwrap();
        let mut reader = csv::Reader::from_reader(out.as_slice());
        let back: Vec<MeasuredRow> = reader.deserialize().collect::<Result<_, _>>().unwrap();
        assert_eq!(back, vec![full]);
        let json = serde_json::to_value(full).unwrap();
        let keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        let mut names: Vec<&str> = all.iter().map(|c| c.name()).collect();
        names.sort_unstable();
        let mut keys = keys;
        keys.sort_unstable();
        assert_eq!(keys, names);
        assert_eq!(json["backdriven"], 1);
    }

    #[test]
    fn a_row_stays_small() {
        // Synthetic sweeps hold their rows in memory before explain takes them as columns
        // (a million rows: 208 MB at this size); a new field costs 16 bytes a row.
        assert!(std::mem::size_of::<MeasuredRow>() <= 208);
    }

    #[test]
    fn backdriven_reads_the_spellings_people_write_and_refuses_others() {
        let read = |cell: &str| {
            let text = format!("omega_n_rad_s,tau_rot_nm,backdriven\n31.4,1.0,{cell}\n");
            csv::Reader::from_reader(text.as_bytes())
                .deserialize::<MeasuredRow>()
                .next()
                .unwrap()
                .map(|r| r.backdriven)
        };
        for (cell, want) in [
            ("1", Some(true)),
            ("0", Some(false)),
            ("true", Some(true)),
            ("No", Some(false)),
            ("", None),
        ] {
            assert_eq!(read(cell).unwrap(), want, "{cell}");
        }
        let e = read("2").unwrap_err().to_string();
        assert!(e.contains("1 (backdriven) or 0 (held)"), "{e}");
        // A column the file lacks is none.
        let r = csv::Reader::from_reader("omega_n_rad_s,tau_rot_nm\n31.4,1.0\n".as_bytes())
            .deserialize::<MeasuredRow>()
            .next()
            .unwrap()
            .unwrap();
        assert_eq!(r.backdriven, None);
        assert!(!EXPERIMENT_SWEEP.is_complete(&r));
        assert!(EXPERIMENT_SWEEP.is_complete(&row()));
    }
}

//! Data as columns for numpy and pandas: each column a (name, dtype, value) triple, the
//! value little-endian bytes for `numpy.frombuffer` (dtype `<f8`, `<u4`, ...) or a list
//! of strings (dtype `str`). Names and units are the CLI's CSV columns: `rig monitor
//! --csv` for telemetry, `rig capture --csv` for captures.

use host::client::{Capture, cam_angle_rad, current_amps, output_angle_rad};
use host::monitor::{CSV_HEADER as TELEMETRY_CSV_HEADER, MonitorRow};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};

use host::recording::{STREAM_CSV_COLUMNS, StreamRow};

use crate::worker::Row;

/// (name, dtype, bytes or list of str) per column.
pub type TypedColumns<'py> = Vec<(&'static str, &'static str, Bound<'py, PyAny>)>;

fn f64_bytes<'py>(py: Python<'py>, values: impl Iterator<Item = f64>) -> Bound<'py, PyAny> {
    let bytes: Vec<u8> = values.flat_map(f64::to_le_bytes).collect();
    PyBytes::new(py, &bytes).into_any()
}

fn opt(v: Option<f32>) -> f64 {
    v.map_or(f64::NAN, f64::from)
}

fn count(v: Option<u32>) -> f64 {
    v.map_or(f64::NAN, f64::from)
}

/// One numeric value of the monitor CSV's column `name` (`rig monitor`'s own row: NaN where
/// the CSV is empty; None: a text column).
fn number(name: &str, r: &MonitorRow) -> Option<f64> {
    Some(match name {
        "device_time_s" => r.device_time_s,
        "cam_speed_rad_s" => f64::from(r.cam_speed_rad_s),
        "cam_hz" => f64::from(r.cam_speed_rad_s.abs() / std::f32::consts::TAU),
        "current_a" => f64::from(r.current_a),
        "pwm_duty" => f64::from(r.pwm_duty),
        "tau_cam_nm" => opt(r.tau_cam_nm),
        "tau_rot_nm" => opt(r.tau_rot_nm),
        "output_rad" => opt(r.output_rad),
        "output_rad_s" => opt(r.output_rad_s),
        "bus_v" => opt(r.bus_v),
        "motor_temp_c" => opt(r.motor_temp_c),
        "step_cycles_mean" => count(r.step_cycles_mean),
        "step_cycles_max" => count(r.step_cycles_max),
        _ => return None,
    })
}

/// One text value of the monitor CSV's column `name`.
fn text(name: &str, r: &MonitorRow) -> String {
    match name {
        "state" => r.state.to_owned(),
        "faults" => r.faults.join("|"),
        "status" => r.status.join("|"),
        _ => String::new(),
    }
}

/// Telemetry rows as the monitor CSV's columns (every one, in its order), then `seq`, the
/// device's sample counter (a gap there is a lost sample).
pub fn telemetry<'py>(py: Python<'py>, rows: &[Row]) -> PyResult<TypedColumns<'py>> {
    let rows: Vec<MonitorRow> = rows
        .iter()
        .map(|r| MonitorRow::new(&r.sample, r.fresh, r.health.as_ref()))
        .collect();
    let mut out: TypedColumns<'py> = Vec::with_capacity(TELEMETRY_CSV_HEADER.len() + 1);
    for name in TELEMETRY_CSV_HEADER {
        if !matches!(name, "state" | "faults" | "status") {
            let values = rows.iter().map(|r| number(name, r).unwrap_or(f64::NAN));
            out.push((name, "<f8", f64_bytes(py, values)));
        } else {
            let list = PyList::new(py, rows.iter().map(|r| text(name, r)))?;
            out.push((name, "str", list.into_any()));
        }
    }
    let seq: Vec<u8> = rows.iter().flat_map(|r| r.seq.to_le_bytes()).collect();
    out.push(("seq", "<u4", PyBytes::new(py, &seq).into_any()));
    Ok(out)
}

/// A capture as `rig capture --csv`'s columns: `index,t_s,current_adc,current_a,
/// encoder_count,cam_angle_rad`.
pub fn capture<'py>(py: Python<'py>, cap: &Capture) -> PyResult<TypedColumns<'py>> {
    let rate = f64::from(cap.sample_rate_hz.max(1));
    let s = &cap.samples;
    let index: Vec<u8> = s.iter().flat_map(|(i, _)| i.to_le_bytes()).collect();
    let adc: Vec<u8> = s
        .iter()
        .flat_map(|(_, x)| x.current_adc.to_le_bytes())
        .collect();
    let enc: Vec<u8> = s
        .iter()
        .flat_map(|(_, x)| x.encoder_count.to_le_bytes())
        .collect();
    Ok(vec![
        ("index", "<u4", PyBytes::new(py, &index).into_any()),
        (
            "t_s",
            "<f8",
            f64_bytes(py, s.iter().map(|(i, _)| f64::from(*i) / rate)),
        ),
        ("current_adc", "<u2", PyBytes::new(py, &adc).into_any()),
        (
            "current_a",
            "<f8",
            f64_bytes(py, s.iter().map(|(_, x)| current_amps(x.current_adc))),
        ),
        ("encoder_count", "<i4", PyBytes::new(py, &enc).into_any()),
        (
            "cam_angle_rad",
            "<f8",
            f64_bytes(py, s.iter().map(|(_, x)| cam_angle_rad(x.encoder_count))),
        ),
        // The output encoder, held from the latest control step (empty cells in the CSV,
        // NaN here, on a device without one).
        (
            "output_count",
            "<f8",
            f64_bytes(
                py,
                s.iter()
                    .map(|(_, x)| x.output_count.map_or(f64::NAN, f64::from)),
            ),
        ),
        (
            "output_angle_rad",
            "<f8",
            f64_bytes(
                py,
                s.iter()
                    .map(|(_, x)| x.output_count.map_or(f64::NAN, output_angle_rad)),
            ),
        ),
    ])
}

/// Stream samples as `rig record`'s CSV columns (its names and units, without `lost`: the
/// recording's `lost` and `gaps` say what never arrived).
pub fn stream<'py>(py: Python<'py>, rows: &[StreamRow]) -> PyResult<TypedColumns<'py>> {
    let le = |f: &dyn Fn(&StreamRow) -> Vec<u8>| -> Bound<'py, PyAny> {
        let bytes: Vec<u8> = rows.iter().flat_map(f).collect();
        PyBytes::new(py, &bytes).into_any()
    };
    let mut out: TypedColumns<'py> = Vec::with_capacity(STREAM_CSV_COLUMNS.len());
    for name in STREAM_CSV_COLUMNS {
        let column = match name {
            "seq" => ("<u4", le(&|r| r.seq.to_le_bytes().to_vec())),
            "t_s" => ("<f8", f64_bytes(py, rows.iter().map(|r| r.t_s))),
            "current_adc" => ("<u2", le(&|r| r.current_adc.to_le_bytes().to_vec())),
            "current_a" => ("<f8", f64_bytes(py, rows.iter().map(|r| r.current_a))),
            "cam_count" => ("<i8", le(&|r| r.cam_count.to_le_bytes().to_vec())),
            "cam_angle_rad" => ("<f8", f64_bytes(py, rows.iter().map(|r| r.cam_angle_rad))),
            "output_count" => ("<i8", le(&|r| r.output_count.to_le_bytes().to_vec())),
            "output_angle_rad" => (
                "<f8",
                f64_bytes(py, rows.iter().map(|r| r.output_angle_rad)),
            ),
            "duty" => ("<f4", le(&|r| r.duty.to_le_bytes().to_vec())),
            "tau_cam_nm" => ("<f4", le(&|r| r.tau_cam_nm.to_le_bytes().to_vec())),
            "state" => (
                "str",
                PyList::new(py, rows.iter().map(StreamRow::state_name))?.into_any(),
            ),
            "fault_latched" => ("<u1", le(&|r| vec![u8::from(r.fault_latched)])),
            "status" => (
                "str",
                PyList::new(py, rows.iter().map(StreamRow::status_names))?.into_any(),
            ),
            _ => continue,
        };
        out.push((name, column.0, column.1));
    }
    Ok(out)
}

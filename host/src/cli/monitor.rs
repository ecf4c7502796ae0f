//! `rig monitor`: live telemetry. In a terminal, a full-screen view with charts of the
//! current, cam speed, tau_cam and the load estimate, the supervisor state and what the
//! board reports once a second (bus voltage, motor temperature, control-step cycles), the
//! output shaft's angle and speed, and the keys (ratatui); `--plain` (or no terminal)
//! prints one line per sample in 80 columns under a header of the CSV's column names;
//! `--csv FILE` logs every sample. One unit per quantity everywhere (tau in N m); a stale
//! estimate is `-` on screen, an empty CSV field and `null` in JSON.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use clap::Args;
use protocol::{DeviceMessage, HealthSample, StatusFlags, SupervisorState, TelemetrySample};
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Style, Stylize};
use ratatui::symbols::Marker;
use ratatui::text::Line;
use ratatui::widgets::{Axis, Block, Chart, Dataset, GraphType, Paragraph};

use super::connect::{DeviceOpts, interrupt_flag};
use crate::client::LinkStats;
use crate::monitor::HealthValues;
pub use crate::monitor::{CSV_HEADER, Freshness, MonitorRow, STALE_RULE, status_meaning};
use crate::{RigError, args, limits, row_log};

/// Arguments of `rig monitor`.
#[derive(Debug, Args)]
pub struct MonitorArgs {
    /// One line per sample instead of the full-screen view (the default without a terminal).
    #[arg(long)]
    plain: bool,
    /// Also log every sample to this CSV file, a new one (an existing one only with
    /// --resume or --force): each row is appended whole as it arrives, so a monitor killed
    /// in any way leaves its header and whole rows.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Continue an existing --csv log (a monitor's, same columns): rows are appended after
    /// its last whole row; a row cut short (a SIGKILL mid-write, a full disk) is dropped
    /// and said so.
    #[arg(long, requires = "csv", conflicts_with = "force")]
    resume: bool,
    /// Replace an existing --csv file once the monitor ends (q, Ctrl-C, --seconds): until
    /// then it logs to FILE.new and the old file stays whole.
    #[arg(long, requires = "csv")]
    force: bool,
    /// Stop after this many (device) seconds; default: until q or Ctrl-C.
    #[arg(long, value_name = "S", value_parser = args::positive, allow_hyphen_values = true)]
    seconds: Option<f64>,
    /// Telemetry rate, samples per second: 1000 divided by a whole number (1000, 500, 250,
    /// 200, 125, 100, 50, 40, 25, 20, 10, ...).
    #[arg(long, value_name = "HZ", default_value_t = 50, value_parser = clap::value_parser!(u16).range(1..=1000))]
    rate: u16,
    /// Vibrate at this frequency (Hz, at most the calibration's max_freq_hz) while
    /// monitoring; locked again on exit. In the full-screen view `r` toggles the release at
    /// this frequency (default 10 Hz).
    #[arg(long, value_name = "HZ", value_parser = args::positive, allow_hyphen_values = true)]
    release: Option<f64>,
    /// One JSON object per sample (JSON lines) instead of text.
    #[arg(long)]
    json: bool,
    /// Explain the status flags and when estimates are shown as `-`, then exit (no device).
    #[arg(long)]
    explain: bool,
}

/// An estimate for display: `-` when stale.
fn estimate(fresh: bool, v: f32, scale: f32, width: usize, digits: usize) -> String {
    if fresh && v.is_finite() {
        format!("{:width$.digits$}", v * scale)
    } else {
        format!("{:>width$}", "-")
    }
}

/// What a key in the full-screen view asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum KeyAction {
    None,
    Quit,
    ToggleRelease,
}

/// Widest line of `--plain` output, columns.
pub const PLAIN_WIDTH: usize = 80;

/// The column heads of `--plain` output, printed once before the first sample: the CSV's
/// column names (and units), so a line reads the same as a row of `--csv`. The load
/// estimate, the drive's duty, the motor temperature and the step cycles are in the CSV,
/// the JSON and the full-screen view (80 columns hold no more).
pub const PLAIN_HEADER: &str =
    "   time_s state     cam_hz current_a tau_cam_nm bus_v output_rad faults";

/// One sample of `--plain` output, under [`PLAIN_HEADER`], at most [`PLAIN_WIDTH`]
/// columns; the estimates are `-` unless `fresh` ([`Freshness`]), the bus voltage (from
/// the newest `health` report) and the output angle `-` when not reported. Faults that do
/// not fit their column are counted there and listed on the lines below (indented).
pub fn plain_line(t: &TelemetrySample, fresh: bool, health: Option<&HealthSample>) -> String {
    let bus = HealthValues::of(health).bus_v.unwrap_or(f32::NAN);
    let head = format!(
        "{:9.3} {:<9} {:6.2} {:9.3} {} {} {}",
        t.device_time_us as f64 * 1e-6,
        t.state.name(),
        t.cam_speed_rad_s.abs() / std::f32::consts::TAU,
        t.current_a,
        estimate(fresh, t.tau_cam_nm, 1.0, 10, 5),
        estimate(true, bus, 1.0, 5, 2),
        estimate(true, t.output_angle_rad, 1.0, 10, 4),
    );
    let faults = t.faults.to_string().replace(" | ", "|");
    if head.len() + 1 + faults.len() <= PLAIN_WIDTH {
        return format!("{head} {faults}");
    }
    // Too many to fit: the count here, the names below, wrapped at '|'.
    let names: Vec<&str> = faults.split('|').collect();
    let mut text = match names.len() {
        1 => format!("{head} 1 fault:"),
        n => format!("{head} {n} faults:"),
    };
    const INDENT: &str = "          ";
    let mut line = String::from(INDENT);
    for (k, name) in names.iter().enumerate() {
        let piece = if k + 1 < names.len() {
            format!("{name}|")
        } else {
            (*name).to_owned()
        };
        if line.len() > INDENT.len() && line.len() + piece.len() > PLAIN_WIDTH {
            text.push('\n');
            text.push_str(&line);
            line = String::from(INDENT);
        }
        line.push_str(&piece);
    }
    text.push('\n');
    text.push_str(&line);
    text
}

/// The full-screen view's state: the last [`MonitorView::WINDOW_S`] seconds of samples.
#[derive(Debug, Default)]
pub struct MonitorView {
    history: VecDeque<(TelemetrySample, bool)>,
    health: Option<HealthSample>,
    freshness: Freshness,
    series: [Vec<(f64, f64)>; 4],
    port: String,
    stats: LinkStats,
    /// A message for the operator (the last release toggle's outcome).
    pub note: Option<String>,
}

impl MonitorView {
    /// Seconds of history on the charts.
    pub const WINDOW_S: f64 = 10.0;

    /// An empty view of the device on `port`.
    pub fn new(port: &str) -> Self {
        Self {
            port: port.to_owned(),
            ..Self::default()
        }
    }

    /// Adds a sample, forgetting those older than the window; returns whether its
    /// estimates are current ([`Freshness`]).
    pub fn push(&mut self, t: TelemetrySample) -> bool {
        let now = t.device_time_us;
        let fresh = self.freshness.update(&t);
        self.history.push_back((t, fresh));
        while self
            .history
            .front()
            .is_some_and(|f| (now - f.0.device_time_us) as f64 * 1e-6 > Self::WINDOW_S)
        {
            self.history.pop_front();
        }
        fresh
    }

    /// Records the board's newest once-a-second report.
    pub fn set_health(&mut self, health: HealthSample) {
        self.health = Some(health);
    }

    /// The board's newest report, if one came.
    pub fn health(&self) -> Option<&HealthSample> {
        self.health.as_ref()
    }

    /// Records the link counters to show.
    pub fn set_stats(&mut self, stats: LinkStats) {
        self.stats = stats;
    }

    /// Draws the view into `frame`.
    pub fn render(&mut self, frame: &mut Frame<'_>) {
        let [status, top, bottom] = Layout::vertical([
            Constraint::Length(8),
            Constraint::Fill(1),
            Constraint::Fill(1),
        ])
        .areas(frame.area());
        let [a, b] = Layout::horizontal([Constraint::Fill(1); 2]).areas(top);
        let [c, d] = Layout::horizontal([Constraint::Fill(1); 2]).areas(bottom);
        frame.render_widget(self.status(), status);
        let now = self.history.back().map_or(0, |t| t.0.device_time_us);
        let values: [fn(&TelemetrySample) -> f64; 4] = [
            |t| f64::from(t.current_a),
            |t| f64::from(t.cam_speed_rad_s.abs()) / std::f64::consts::TAU,
            |t| f64::from(t.tau_cam_nm),
            |t| f64::from(t.tau_rot_nm),
        ];
        for (k, value) in values.iter().enumerate() {
            // The estimates (charts 3 and 4) only where they are current.
            self.series[k] = self
                .history
                .iter()
                .filter(|(_, fresh)| k < 2 || *fresh)
                .map(|(t, _)| (-((now - t.device_time_us) as f64) * 1e-6, value(t)))
                .collect();
        }
        let titles = [
            ("current i_in, A", Color::Yellow),
            ("cam speed, Hz", Color::Cyan),
            ("tau_cam (estimate), N m", Color::Green),
            ("load tau_rot (estimate), N m", Color::Magenta),
        ];
        for ((area, series), (title, color)) in
            [a, b, c, d].into_iter().zip(&self.series).zip(titles)
        {
            render_chart(frame, area, title, color, series);
        }
    }

    fn status(&self) -> Paragraph<'static> {
        let Some(&(t, fresh)) = self.history.back() else {
            return Paragraph::new(format!("waiting for telemetry from {} ...", self.port))
                .block(Block::bordered().title(" rig monitor "));
        };
        let state_color = match t.state {
            SupervisorState::Locked => Color::Green,
            SupervisorState::SpinUp | SupervisorState::Stopping => Color::Yellow,
            SupervisorState::Vibrating => Color::Cyan,
            _ => Color::Red,
        };
        // Every line fits 78 columns (an 80-column terminal inside the border).
        let line1 = Line::from(vec![
            "state ".into(),
            t.state.name().to_uppercase().fg(state_color).bold(),
            format!(
                "  t {:.2} s  cam {:.2} Hz  i {:.3} A  duty {:+.3}",
                t.device_time_us as f64 * 1e-6,
                t.cam_speed_rad_s.abs() / std::f32::consts::TAU,
                t.current_a,
                t.pwm_duty,
            )
            .into(),
        ]);
        let faults = if t.faults.is_empty() {
            "faults none".to_owned().fg(Color::Green)
        } else {
            format!("faults {}", t.faults).fg(Color::Red).bold()
        };
        let line2 = Line::from(vec![
            format!(
                "tau_cam {} N m  tau_rot {} N m  ",
                estimate(fresh, t.tau_cam_nm, 1.0, 1, 4).trim(),
                estimate(fresh, t.tau_rot_nm, 1.0, 1, 3).trim()
            )
            .into(),
            faults,
        ]);
        let h = HealthValues::of(self.health.as_ref());
        let (bus, temp) = (
            h.bus_v.unwrap_or(f32::NAN),
            h.motor_temp_c.unwrap_or(f32::NAN),
        );
        let cycles = match (h.step_cycles_mean, h.step_cycles_max) {
            (Some(m), Some(x)) => format!("{m}/{x} cyc"),
            _ => "- cyc".into(),
        };
        let board = Line::from(format!(
            "bus {} V  motor {} C  step {cycles}  output {} rad {} rad/s",
            estimate(true, bus, 1.0, 1, 2).trim(),
            estimate(true, temp, 1.0, 1, 1).trim(),
            estimate(true, t.output_angle_rad, 1.0, 1, 3).trim(),
            estimate(true, t.output_speed_rad_s, 1.0, 1, 2).trim(),
        ));
        let line3 = Line::from(format!(
            "status {}  link {} frames, {} bad, {} lost",
            if t.status.is_empty() {
                "none".to_string()
            } else {
                t.status.to_string()
            },
            self.stats.frames_ok,
            self.stats.frame_errors,
            self.stats.telemetry_lost
        ));
        // The legend: what the flags set now mean (all of them: `rig monitor --explain`).
        let legend: Vec<String> = t
            .status
            .names()
            .filter_map(|name| status_meaning(name).map(|m| format!("{name}: {m}")))
            .collect();
        let line4 = Line::from(if legend.is_empty() {
            "`-`: not reported, or an estimate stale (locked, fault, no turn in 1 s)".to_string()
        } else {
            legend.join("; ")
        })
        .fg(Color::DarkGray);
        let line5 = Line::from(self.note.clone().unwrap_or_default()).fg(Color::Yellow);
        Paragraph::new(vec![line1, line2, board, line3, line4, line5])
            .wrap(ratatui::widgets::Wrap { trim: true })
            .block(
                Block::bordered()
                    .title(format!(" rig monitor: {} ", self.port))
                    .title_bottom(" keys: r release/lock  q quit "),
            )
    }
}

fn render_chart(
    frame: &mut Frame<'_>,
    area: Rect,
    title: &str,
    color: Color,
    series: &[(f64, f64)],
) {
    let (lo, hi) = series
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.1), hi.max(p.1))
        });
    let (lo, hi) = if lo.is_finite() {
        let pad = ((hi - lo) * 0.1).max(1e-3 * hi.abs().max(1.0));
        (lo - pad, hi + pad)
    } else {
        (0.0, 1.0)
    };
    let dataset = Dataset::default()
        .marker(Marker::Braille)
        .graph_type(GraphType::Line)
        .style(Style::default().fg(color))
        .data(series);
    let chart = Chart::new(vec![dataset])
        .block(Block::bordered().title(format!(" {title} ")))
        .x_axis(
            Axis::default()
                .bounds([-MonitorView::WINDOW_S, 0.0])
                .labels([format!("-{:.0} s", MonitorView::WINDOW_S), "now".into()]),
        )
        .y_axis(Axis::default().bounds([lo, hi]).labels(axis_labels(lo, hi)));
    frame.render_widget(chart, area);
}

/// A chart's y-axis ends with as many decimals as their span needs to tell them apart
/// (tau_cam of a few mN m read `0.00` and `0.00` at two decimals).
fn axis_labels(lo: f64, hi: f64) -> [String; 2] {
    let span = (hi - lo).abs();
    let decimals = if span > 0.0 && span.is_finite() {
        (1.0 - span.log10().floor()).clamp(2.0, 6.0) as usize
    } else {
        2
    };
    [format!("{lo:.decimals$}"), format!("{hi:.decimals$}")]
}

/// Runs `rig monitor`.
pub fn run(a: MonitorArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    if a.explain {
        let mut out = std::io::stdout().lock();
        writeln!(out, "status flags:")?;
        for protocol::FlagInfo {
            name,
            help: meaning,
            ..
        } in StatusFlags::TABLE
        {
            writeln!(out, "  {name:<21} {meaning}")?;
        }
        writeln!(out, "{STALE_RULE}")?;
        writeln!(out, "faults: `rig faults` names them and what to do")?;
        return Ok(ExitCode::SUCCESS);
    }
    // The firmware would send at its control rate divided by a whole number.
    limits::check_telemetry_rate("--rate", a.rate)?;
    match &a.csv {
        Some(path) => log_to(path, &a, dev)?,
        None => watch(&a, dev, None)?,
    }
    // Ended by SIGTERM, SIGHUP or Ctrl-C (not `q`): 128 + the signal's number.
    Ok(crate::signals::exit_code())
}

/// The monitor itself: connects, streams telemetry until done, logs every sample to `log`.
fn watch(a: &MonitorArgs, dev: &DeviceOpts, mut log: Option<&mut Log>) -> Result<(), RigError> {
    let stop = interrupt_flag();
    let mut s = dev.connect()?;
    let calibration = s.client.calibration()?;
    // The firmware would drive a frequency above the calibration's maximum at that maximum.
    let release_hz = match a.release {
        Some(hz) => limits::check_release_freq("--release", hz, &calibration)?,
        None => 10.0f32.min(limits::release_freq_range(&calibration).1),
    };
    s.client.start_telemetry(a.rate)?;
    let full_screen =
        !a.plain && !a.json && std::io::stdout().is_terminal() && std::io::stdin().is_terminal();
    let mut terminal = if full_screen {
        Some(ratatui::try_init().map_err(RigError::Output)?)
    } else {
        None
    };
    let mut released = false;
    if a.release.is_some() {
        s.client.release(true, release_hz)?;
        released = true;
    }
    let mut view = MonitorView::new(s.port());
    let mut out = std::io::stdout().lock();
    let mut first = None;
    let mut count = 0u64;
    let mut last_draw = Instant::now() - Duration::from_secs(1);
    let result = (|| -> Result<(), RigError> {
        loop {
            if stop.load(Ordering::SeqCst) {
                return Ok(());
            }
            if terminal.is_some() {
                match key_action()? {
                    KeyAction::Quit => return Ok(()),
                    KeyAction::ToggleRelease => {
                        let on = !released;
                        view.note = Some(match s.client.release(on, release_hz) {
                            Ok(()) => {
                                released = on;
                                if on {
                                    format!("released at {release_hz} Hz: the load can move")
                                } else {
                                    "locked".into()
                                }
                            }
                            Err(e) => e.to_string(),
                        });
                    }
                    KeyAction::None => {}
                }
            }
            let t = match s.client.recv(Duration::from_millis(30))? {
                Some(DeviceMessage::Telemetry(t)) => Some(t),
                Some(DeviceMessage::Health(h)) => {
                    view.set_health(h);
                    None
                }
                _ => None,
            };
            if let Some(t) = t {
                count += 1;
                let start = *first.get_or_insert(t.device_time_us);
                let fresh = view.push(t);
                if let Some(log) = log.as_deref_mut() {
                    log.row(&MonitorRow::new(&t, fresh, view.health()))?;
                }
                if a.json {
                    super::print_json_line(&mut out, &MonitorRow::new(&t, fresh, view.health()))?;
                } else if terminal.is_none() {
                    if count == 1 {
                        writeln!(out, "{PLAIN_HEADER}")?;
                    }
                    writeln!(out, "{}", plain_line(&t, fresh, view.health()))?;
                }
                if a.seconds
                    .is_some_and(|limit| (t.device_time_us - start) as f64 * 1e-6 >= limit)
                {
                    return Ok(());
                }
            }
            if let Some(term) = terminal.as_mut()
                && last_draw.elapsed() >= Duration::from_millis(50)
            {
                view.set_stats(s.client.stats());
                term.draw(|f| view.render(f)).map_err(RigError::Output)?;
                last_draw = Instant::now();
            }
        }
    })();
    if terminal.is_some() {
        let _ = ratatui::try_restore();
    }
    // A reader that went away (`rig monitor --plain | head`) ends the monitor normally.
    let result = match result {
        Err(RigError::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    };
    if released {
        // Lock before leaving; should this fail, the device stops at its comms timeout.
        let _ = s.client.release(false, 0.0);
    }
    let _ = s.client.stop_telemetry();
    result?;
    if !a.json {
        let st = s.client.stats();
        eprintln!(
            "{count} samples; {} lost in the stream, {} bad frames",
            st.telemetry_lost, st.frame_errors
        );
    }
    Ok(())
}

/// The `--csv` log being written: its rows appended whole ([`row_log::Appender`]).
#[derive(Debug)]
struct Log {
    out: row_log::Appender,
    /// Rows this run logged.
    rows: u64,
}

impl Log {
    fn row(&mut self, row: &MonitorRow) -> Result<(), RigError> {
        self.out.write(&csv_line(&row.csv_record()))?;
        self.rows += 1;
        Ok(())
    }
}

/// `fields` as one CSV line (quoted as the csv crate quotes), newline included.
fn csv_line(fields: &[String]) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing to memory cannot fail.
    let _ = w.write_record(fields);
    String::from_utf8_lossy(&w.into_inner().unwrap_or_default()).into_owned()
}

/// How often the log is synced to disk (rows reach the file at every write).
const LOG_SYNC: row_log::Sync = row_log::Sync::Every(Duration::from_secs(1));

/// Runs the monitor logging to `path`: a new file is written directly, row by row; an
/// existing one only with `--resume` (appended to, after dropping a row cut short) or
/// `--force` (FILE.new, renamed over it when the monitor ends normally).
fn log_to(path: &Path, a: &MonitorArgs, dev: &DeviceOpts) -> Result<(), RigError> {
    let name = path.display().to_string();
    // A folder, FIFO or device is no log: writing or reading one would fail or block.
    if let Some(why) = rigfile::text_input::not_a_regular_file(path) {
        return Err(RigError::BadValue {
            what: format!("--csv {name}"),
            why: why.replace("save it to a file first", "give a file name"),
        });
    }
    let exists = path.exists();
    let header = csv_line(&CSV_HEADER.map(String::from));
    if exists && !a.resume && !a.force {
        let half = row_log::tail_half_row(path).unwrap_or(0);
        let cut = if half > 0 {
            format!(" (it ends in a row cut short, {half} bytes, which --resume drops)")
        } else {
            String::new()
        };
        return Err(RigError::BadValue {
            what: format!("--csv {name}"),
            why: format!(
                "already exists{cut}: it was left unchanged; pass --resume to continue it, --force to replace it, or give a new file name"
            ),
        });
    }
    let replaces = (exists && a.force).then(|| crate::experiment::sweep::forced_path(path));
    let mut log = if exists && a.resume {
        check_monitor_log(path, &header)?;
        let file = row_log::open_to_continue(path, &mut |l| eprintln!("{l}"))?;
        let mut out = row_log::Appender::new(file, name.clone(), LOG_SYNC)?;
        if out.is_empty() {
            out.write(&header)?;
        }
        Log { out, rows: 0 }
    } else {
        let target = replaces.as_deref().unwrap_or(path);
        if let Some(new) = &replaces
            && new.exists()
        {
            return Err(RigError::BadValue {
                what: format!("--csv {name} --force"),
                why: format!(
                    "{} is there already: the rows of an interrupted --force monitor (or one still running); move it away, or rename it over {name} and continue it with --resume (nothing was written)",
                    new.display()
                ),
            });
        }
        let file = crate::experiment::sweep::create_new(target, false)?;
        let mut out = row_log::Appender::new(file, target.display().to_string(), LOG_SYNC)?;
        if let Err(e) = out.write(&header) {
            let _ = std::fs::remove_file(target);
            return Err(e);
        }
        Log { out, rows: 0 }
    };
    let created = !(exists && a.resume);
    let written = replaces.as_deref().unwrap_or(path);
    let watched = watch(a, dev, Some(&mut log));
    let result = watched.and_then(|()| log.out.sync());
    if let Err(e) = result {
        if created && log.rows == 0 {
            // Nothing measured: no file of a header alone is left behind.
            let _ = std::fs::remove_file(written);
        } else {
            let old = if replaces.is_some() {
                format!("; {name} was left as it was")
            } else {
                String::new()
            };
            eprintln!(
                "note: the {} rows logged before the error are in {}, each whole{old}",
                log.rows,
                written.display()
            );
        }
        return Err(e);
    }
    drop(log);
    if let Some(new) = replaces {
        std::fs::rename(&new, path).map_err(|source| RigError::File {
            action: "replace",
            path: name,
            source,
        })?;
    }
    Ok(())
}

/// Refuses to `--resume` a file that is not a monitor log: its first line must be the
/// monitor's header (or the file empty, or the header itself cut short).
fn check_monitor_log(path: &Path, header: &str) -> Result<(), RigError> {
    let mut first = Vec::new();
    let read = File::open(path)
        .and_then(|f| f.take(header.len() as u64).read_to_end(&mut first))
        .map_err(|source| RigError::File {
            action: "read",
            path: path.display().to_string(),
            source,
        })?;
    if header.as_bytes().starts_with(&first[..read]) {
        return Ok(());
    }
    Err(RigError::BadValue {
        what: format!("--resume --csv {}", path.display()),
        why: format!(
            "is not a `rig monitor --csv` log (its first line is not the monitor's header `{}`): it was left unchanged; give a monitor log or a new file name",
            header.trim_end()
        ),
    })
}

/// The key pressed, if any: q, Esc or Ctrl-C quit (the terminal is in raw mode, so Ctrl-C
/// is a key), r toggles the release.
fn key_action() -> Result<KeyAction, RigError> {
    use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
    while event::poll(Duration::ZERO).map_err(RigError::Output)? {
        if let Event::Key(k) = event::read().map_err(RigError::Output)?
            && k.kind == KeyEventKind::Press
        {
            let ctrl_c =
                k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL);
            if ctrl_c || matches!(k.code, KeyCode::Char('q') | KeyCode::Esc) {
                return Ok(KeyAction::Quit);
            }
            if k.code == KeyCode::Char('r') {
                return Ok(KeyAction::ToggleRelease);
            }
        }
    }
    Ok(KeyAction::None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::FaultFlags;
    use ratatui::Terminal;
    use ratatui::backend::TestBackend;

    fn health(bus_v: f32) -> HealthSample {
        HealthSample {
            device_time_us: 1_000_000,
            bus_voltage_v: bus_v,
            motor_temp_c: f32::NAN,
            step_cycles_mean: 0,
            step_cycles_max: 0,
            rx_frame_errors: 0,
            tx_frames_dropped: 0,
        }
    }

    fn sample(ms: u64, state: SupervisorState) -> TelemetrySample {
        TelemetrySample {
            seq: ms as u32,
            device_time_us: ms * 1000,
            cam_speed_rad_s: 62.832,
            current_a: 2.5,
            pwm_duty: 0.3,
            tau_cam_nm: 0.05,
            tau_rot_nm: 1.2,
            state,
            faults: FaultFlags::empty(),
            status: StatusFlags::HOST_RELEASE,
            output_angle_rad: f32::NAN,
            output_speed_rad_s: f32::NAN,
        }
    }

    #[test]
    fn view_renders_state_and_the_four_charts() {
        let mut view = MonitorView::new("/dev/pts/9");
        for ms in (0..12_000).step_by(20) {
            view.push(sample(ms, SupervisorState::Vibrating));
        }
        // The window keeps 10 s.
        assert!(view.history.len() <= 502);
        view.note = Some("released at 10 Hz".into());
        let mut term = Terminal::new(TestBackend::new(120, 40)).unwrap();
        term.draw(|f| view.render(f)).unwrap();
        let text: String = term
            .backend()
            .buffer()
            .content()
            .iter()
            .map(|c| c.symbol())
            .collect();
        for want in [
            "VIBRATING",
            "current i_in",
            "cam speed",
            "tau_cam",
            "tau_rot",
            "10.00 Hz",
            "/dev/pts/9",
            "released at 10 Hz",
        ] {
            assert!(text.contains(want), "missing {want}");
        }
    }

    #[test]
    fn plain_lines_fit_80_columns_with_every_field() {
        let mut t = sample(1500, SupervisorState::Vibrating);
        t.device_time_us = 86_400_000_000; // a day of uptime
        t.current_a = -4.999;
        t.pwm_duty = -1.0;
        t.tau_cam_nm = -0.123_45;
        t.tau_rot_nm = -3.68;
        t.output_angle_rad = -12_345.678;
        assert!(PLAIN_HEADER.len() <= PLAIN_WIDTH);
        let h = health(24.0);
        let one = plain_line(&t, true, Some(&h));
        assert!(!one.contains('\n') && one.len() <= PLAIN_WIDTH, "{one}");
        assert!(one.ends_with(" none"), "{one}");
        // A fault wraps below its count, every name kept.
        t.faults = FaultFlags::OVERCURRENT;
        let one = plain_line(&t, false, Some(&h));
        assert!(
            one.ends_with(" OVERCURRENT") && one.len() <= PLAIN_WIDTH,
            "{one}"
        );
        t.faults = FaultFlags::all();
        let many = plain_line(&t, false, Some(&h));
        let n = FaultFlags::all().names().count();
        assert!(
            many.lines()
                .next()
                .unwrap()
                .ends_with(&format!(" {n} faults:")),
            "{many}"
        );
        for l in many.lines() {
            assert!(l.len() <= PLAIN_WIDTH, "{} columns: {l}", l.len());
        }
        for name in FaultFlags::all().names() {
            assert!(many.contains(name), "{name} missing:\n{many}");
        }
    }

    #[test]
    fn every_status_flag_is_explained() {
        for name in StatusFlags::all().names() {
            assert!(status_meaning(name).is_some(), "{name} has no legend");
        }
    }

    #[test]
    fn estimates_go_stale_when_locked_faulted_or_the_cam_stops() {
        let mut f = Freshness::default();
        let mut t = sample(0, SupervisorState::Vibrating);
        // 10 Hz: a revolution every 0.1 s.
        for ms in (0..300).step_by(10) {
            t.device_time_us = ms * 1000;
            f.update(&t);
        }
        assert!(f.update(&t), "turning and vibrating: current");
        let mut locked = t;
        locked.state = SupervisorState::Locked;
        assert!(!f.update(&locked), "locked: stale");
        let mut faulted = t;
        faulted.faults = FaultFlags::STALL;
        assert!(!f.update(&faulted), "a fault: stale");
        // The cam stops while still Vibrating: stale once 1 s passes without a turn.
        t.cam_speed_rad_s = 0.0;
        t.device_time_us = 900_000;
        assert!(f.update(&t));
        t.device_time_us = 1_400_000;
        assert!(!f.update(&t), "no revolution for over 1 s: stale");
        let line = plain_line(&locked, false, None);
        let cols: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(cols[4], "-", "{line}");
        // Stale in the files too: an empty CSV field and JSON null, not a number.
        let row = MonitorRow::new(&locked, false, None).csv_record();
        assert_eq!((row[6].as_str(), row[7].as_str()), ("", ""));
        let json = serde_json::to_value(MonitorRow::new(&locked, false, None)).unwrap();
        assert!(json["tau_cam_nm"].is_null() && json["tau_rot_nm"].is_null());
        let json = serde_json::to_value(MonitorRow::new(&t, true, None)).unwrap();
        assert_eq!(json["tau_rot_nm"], 1.2);
    }

    #[test]
    fn the_view_fits_80_columns_and_shows_stale_estimates_as_dashes() {
        let mut view = MonitorView::new("/dev/pts/9");
        for ms in (0..3_000).step_by(20) {
            view.push(sample(ms, SupervisorState::Vibrating));
        }
        let mut s = sample(3_000, SupervisorState::Locked);
        s.status = StatusFlags::OUTPUT_MOVING | StatusFlags::COASTS_AFTER_STOP;
        view.push(s);
        view.set_health(health(12.5));
        let mut term = Terminal::new(TestBackend::new(80, 24)).unwrap();
        term.draw(|f| view.render(f)).unwrap();
        let buf = term.backend().buffer().clone();
        let rows: Vec<String> = (0..24)
            .map(|y| (0..80).map(|x| buf[(x, y)].symbol()).collect())
            .collect();
        let text = rows.join("\n");
        for want in [
            "LOCKED",
            "tau_cam - N m",
            "tau_rot - N m",
            "OUTPUT_MOVING: the output shaft turns",
            "faults none",
            "bus 12.50 V",
            "motor - C",
            "output - rad",
            "r release/lock",
            "q quit",
        ] {
            assert!(text.contains(want), "missing {want}:\n{text}");
        }
    }

    #[test]
    fn plain_line_and_csv_row_agree() {
        let t = sample(1500, SupervisorState::Locked);
        let line = plain_line(&t, false, None);
        let cols: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(&cols[..3], ["1.500", "locked", "10.00"], "{line}");
        // The header names the CSV's columns, each above its values.
        let heads: Vec<&str> = PLAIN_HEADER.split_whitespace().collect();
        assert_eq!(
            heads,
            [
                "time_s",
                "state",
                "cam_hz",
                "current_a",
                "tau_cam_nm",
                "bus_v",
                "output_rad",
                "faults"
            ]
        );
        for h in &heads[2..7] {
            assert!(CSV_HEADER.contains(h), "{h}");
        }
        let mut fresh = t;
        fresh.tau_cam_nm = 0.016_48;
        fresh.tau_rot_nm = 0.368;
        fresh.output_angle_rad = -0.25;
        let line = plain_line(&fresh, true, Some(&health(12.05)));
        let end_of = |text: &str, word: &str| text.find(word).unwrap() + word.len();
        for (k, h) in heads.iter().enumerate().take(7).skip(2) {
            // Right-aligned numbers end under their head.
            let value = line.split_whitespace().nth(k).unwrap();
            assert_eq!(end_of(&line, value), end_of(PLAIN_HEADER, h), "{h}: {line}");
        }
        assert!(
            line.contains(" 0.01648 ") && line.contains(" 12.05 "),
            "{line}"
        );
        assert!(line.contains(" -0.2500 "), "{line}");
        let row = MonitorRow::new(&fresh, true, Some(&health(12.05))).csv_record();
        assert_eq!(row.len(), CSV_HEADER.len());
        assert_eq!(row[1], "locked");
        assert_eq!(row[9], "HOST_RELEASE");
        assert_eq!((row[10].as_str(), row[12].as_str()), ("-0.25000", "12.050"));
        // Not sensed (NaN) and not measured (0 cycles): empty.
        assert_eq!((row[13].as_str(), row[14].as_str()), ("", ""));
    }

    #[test]
    fn chart_axis_ends_are_told_apart() {
        // A cam torque of 14-15 mN m, padded: two decimals read 0.01 and 0.02 at best.
        let [lo, hi] = axis_labels(0.0139, 0.0153);
        assert_eq!((lo.as_str(), hi.as_str()), ("0.0139", "0.0153"));
        let [lo, hi] = axis_labels(-0.5, 2.5);
        assert_eq!((lo.as_str(), hi.as_str()), ("-0.50", "2.50"));
    }
}

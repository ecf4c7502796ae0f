//! Serial ports of this machine, with USB identities read from sysfs (so the tool builds
//! without libudev), and the ST-LINK virtual COM ports of Nucleo boards marked.

use std::path::{Path, PathBuf};

/// USB vendor id of STMicroelectronics.
pub const ST_VID: u16 = 0x0483;

/// USB product ids of ST-LINK probes with a virtual COM port (V2-1, V3 variants).
pub const STLINK_PIDS: [u16; 6] = [0x374B, 0x374E, 0x374F, 0x3752, 0x3753, 0x3754];

/// One serial port.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct PortInfo {
    /// Device path, e.g. `/dev/ttyACM0`.
    pub port: String,
    /// `usb`, `pci`, `serial` (an on-board UART) or `other`.
    pub kind: String,
    /// USB vendor id, when on USB.
    pub vid: Option<u16>,
    /// USB product id, when on USB.
    pub pid: Option<u16>,
    /// USB manufacturer string.
    pub manufacturer: Option<String>,
    /// USB product string.
    pub product: Option<String>,
    /// USB serial number.
    pub serial_number: Option<String>,
    /// Whether this is an ST-LINK virtual COM port (a Nucleo board's UART).
    pub stlink: bool,
}

/// Whether a USB vendor/product id pair is an ST-LINK virtual COM port.
pub fn is_stlink(vid: u16, pid: u16) -> bool {
    vid == ST_VID && STLINK_PIDS.contains(&pid)
}

/// The serial ports of this machine, ST-LINK ports first.
pub fn list() -> Vec<PortInfo> {
    if cfg!(target_os = "linux") {
        scan_sysfs(Path::new("/sys/class/tty"), Path::new("/dev"))
    } else {
        serialport::available_ports()
            .unwrap_or_default()
            .into_iter()
            .map(|p| {
                let mut info = PortInfo {
                    port: p.port_name,
                    kind: "other".into(),
                    vid: None,
                    pid: None,
                    manufacturer: None,
                    product: None,
                    serial_number: None,
                    stlink: false,
                };
                if let serialport::SerialPortType::UsbPort(u) = p.port_type {
                    info.kind = "usb".into();
                    info.vid = Some(u.vid);
                    info.pid = Some(u.pid);
                    info.stlink = is_stlink(u.vid, u.pid);
                    info.manufacturer = u.manufacturer;
                    info.product = u.product;
                    info.serial_number = u.serial_number;
                }
                info
            })
            .collect()
    }
}

/// Reads the ports from a sysfs tty class folder (`/sys/class/tty`) whose device nodes are
/// in `dev`. Ports without a backing device (virtual consoles, ptys) are left out.
pub fn scan_sysfs(class_tty: &Path, dev: &Path) -> Vec<PortInfo> {
    let Ok(entries) = std::fs::read_dir(class_tty) else {
        return Vec::new();
    };
    let mut ports: Vec<PortInfo> = entries
        .flatten()
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            let device = entry.path().join("device");
            let device = device.canonicalize().ok()?;
            let kind = subsystem(&device)?;
            // The 8250 driver registers placeholder ports with no UART behind them (type 0).
            if name.starts_with("ttyS")
                && read_text(&entry.path().join("type")).as_deref() == Some("0")
            {
                return None;
            }
            let node = dev.join(&name);
            if !node.exists() {
                return None;
            }
            let mut info = PortInfo {
                port: node.to_string_lossy().into_owned(),
                kind: match kind.as_str() {
                    "usb" | "usb-serial" => "usb".into(),
                    "pci" => "pci".into(),
                    _ => "serial".into(),
                },
                vid: None,
                pid: None,
                manufacturer: None,
                product: None,
                serial_number: None,
                stlink: false,
            };
            if let Some(usb) = usb_device_dir(&device) {
                info.vid = read_hex(&usb.join("idVendor"));
                info.pid = read_hex(&usb.join("idProduct"));
                info.manufacturer = read_text(&usb.join("manufacturer"));
                info.product = read_text(&usb.join("product"));
                info.serial_number = read_text(&usb.join("serial"));
                info.stlink = matches!((info.vid, info.pid), (Some(v), Some(p)) if is_stlink(v, p));
            }
            Some(info)
        })
        .collect();
    ports.sort_by(|a, b| b.stlink.cmp(&a.stlink).then_with(|| a.port.cmp(&b.port)));
    ports
}

/// The bus a tty's device sits on (`usb`, `usb-serial`, `pci`, `pnp`, `platform`, ...).
fn subsystem(device: &Path) -> Option<String> {
    let link = device.join("subsystem").canonicalize().ok()?;
    Some(link.file_name()?.to_string_lossy().into_owned())
}

/// The USB device folder (the one with `idVendor`) above a tty's device: its parent for
/// CDC-ACM (the ST-LINK), two up for usb-serial adapters.
fn usb_device_dir(device: &Path) -> Option<PathBuf> {
    device
        .ancestors()
        .skip(1)
        .take(3)
        .find(|dir| dir.join("idVendor").is_file())
        .map(Path::to_path_buf)
}

fn read_text(path: &Path) -> Option<String> {
    let s = std::fs::read_to_string(path).ok()?;
    let s = s.trim();
    (!s.is_empty()).then(|| s.to_owned())
}

fn read_hex(path: &Path) -> Option<u16> {
    u16::from_str_radix(&read_text(path)?, 16).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fake sysfs with an ST-LINK on ttyACM0, an FTDI adapter on ttyUSB0, a placeholder
    /// ttyS3 and a virtual console tty1.
    fn fake_sysfs(root: &Path) {
        let mk = |p: &Path| std::fs::create_dir_all(p).unwrap();
        let write = |p: PathBuf, s: &str| std::fs::write(p, s).unwrap();
        let devices = root.join("devices");
        let bus = root.join("bus");
        for b in ["usb", "usb-serial", "platform"] {
            mk(&bus.join(b));
        }
        let class = root.join("class/tty");
        let dev = root.join("dev");
        mk(&class);
        mk(&dev);
        // ST-LINK: class/tty/ttyACM0/device -> devices/usb1/1-1/1-1:1.2 (interface).
        let stlink = devices.join("usb1/1-1");
        let acm_if = stlink.join("1-1:1.2");
        mk(&acm_if);
        write(stlink.join("idVendor"), "0483\n");
        write(stlink.join("idProduct"), "374b\n");
        write(stlink.join("product"), "STM32 STLink\n");
        write(stlink.join("serial"), "066FFF\n");
        std::os::unix::fs::symlink(bus.join("usb"), acm_if.join("subsystem")).unwrap();
        mk(&class.join("ttyACM0"));
        std::os::unix::fs::symlink(&acm_if, class.join("ttyACM0/device")).unwrap();
        write(dev.join("ttyACM0"), "");
        // FTDI: device is devices/usb1/1-2/1-2:1.0/ttyUSB0 on bus usb-serial.
        let ftdi = devices.join("usb1/1-2");
        let ftdi_port = ftdi.join("1-2:1.0/ttyUSB0");
        mk(&ftdi_port);
        write(ftdi.join("idVendor"), "0403\n");
        write(ftdi.join("idProduct"), "6001\n");
        std::os::unix::fs::symlink(bus.join("usb-serial"), ftdi_port.join("subsystem")).unwrap();
        mk(&class.join("ttyUSB0"));
        std::os::unix::fs::symlink(&ftdi_port, class.join("ttyUSB0/device")).unwrap();
        write(dev.join("ttyUSB0"), "");
        // ttyS3: a placeholder (type 0); ttyS0: a 16550A (type 4); tty1: no device at all.
        let serial8250 = devices.join("platform/serial8250");
        mk(&serial8250);
        std::os::unix::fs::symlink(bus.join("platform"), serial8250.join("subsystem")).unwrap();
        for (name, ty) in [("ttyS3", "0\n"), ("ttyS0", "4\n")] {
            mk(&class.join(name));
            std::os::unix::fs::symlink(&serial8250, class.join(name).join("device")).unwrap();
            write(class.join(name).join("type"), ty);
            write(dev.join(name), "");
        }
        mk(&class.join("tty1"));
        write(dev.join("tty1"), "");
    }

    #[test]
    fn sysfs_scan_finds_and_marks_the_stlink() {
        let tmp = tempfile::tempdir().unwrap();
        fake_sysfs(tmp.path());
        let ports = scan_sysfs(&tmp.path().join("class/tty"), &tmp.path().join("dev"));
        assert_eq!(ports.len(), 3, "{ports:?}");
        assert!(ports[0].port.ends_with("ttyACM0"));
        assert!(ports[0].stlink);
        assert_eq!((ports[0].vid, ports[0].pid), (Some(0x0483), Some(0x374B)));
        assert_eq!(ports[0].product.as_deref(), Some("STM32 STLink"));
        let by_name = |n: &str| ports.iter().find(|p| p.port.ends_with(n)).unwrap();
        let ftdi = by_name("ttyUSB0");
        assert!(!ftdi.stlink);
        assert_eq!(ftdi.vid, Some(0x0403));
        assert_eq!(ftdi.kind, "usb");
        assert_eq!(by_name("ttyS0").kind, "serial");
    }

    #[test]
    fn stlink_ids() {
        assert!(is_stlink(0x0483, 0x374E));
        assert!(!is_stlink(0x0483, 0x5740));
        assert!(!is_stlink(0x0403, 0x374B));
    }

    #[test]
    fn missing_sysfs_is_an_empty_list() {
        assert!(scan_sysfs(Path::new("/nonexistent/class/tty"), Path::new("/dev")).is_empty());
    }
}

//! `viewer view` starts under Xvfb (lavapipe when there is no GPU) on a store written by
//! `ingest`, streams until converged, and puts a non-blank frame with the statistics panel on
//! the X screen: checked on a real screenshot of the root window (`GetImage`), and on the
//! window title; then follows the keys and the mouse (a channel hidden, an orbit, a zoom, the
//! statistics hidden, another mode, quit). Also: `view --help` lists the controls.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use residency_ingest::ConvertOptions;
use x11rb::CURRENT_TIME;
use x11rb::connection::Connection;
use x11rb::protocol::xproto::{
    AtomEnum, BUTTON_PRESS_EVENT, BUTTON_RELEASE_EVENT, ConnectionExt, ImageFormat, ImageOrder,
    InputFocus, KEY_PRESS_EVENT, KEY_RELEASE_EVENT, MOTION_NOTIFY_EVENT,
};
use x11rb::protocol::xtest::ConnectionExt as _;

/// Kills (and reaps) a child process when dropped.
pub(crate) struct Reaped(pub(crate) Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `cmd` (reaped on drop) with its stdout's lines sent to a channel as they come and
/// its stderr gathered by a thread (joined for the whole text).
pub(crate) fn spawn_with_lines(
    cmd: &mut Command,
) -> (
    Reaped,
    std::sync::mpsc::Receiver<String>,
    std::thread::JoinHandle<String>,
) {
    let child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = Reaped(child);
    let stdout = child.0.stdout.take().unwrap();
    let mut stderr = child.0.stderr.take().unwrap();
    let err_thread = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx, err_thread)
}

pub(crate) const SCREEN: (u16, u16) = (480, 360);
const WINDOW: (u32, u32) = (320, 240);

/// The built-in synthetic sample (3 channels, 32 × 64 × 64), bricks of 16³.
pub(crate) fn store(dir: &Path) -> PathBuf {
    let tiffs =
        residency_ingest::synthetic::write_sample(&dir.join("sample"), [32, 64, 64], 1, false)
            .unwrap();
    let out = dir.join("sample.ome.zarr");
    let mut o = ConvertOptions::new(
        tiffs
            .iter()
            .map(|p| p.to_str().unwrap().to_string())
            .collect(),
        out.clone(),
    );
    o.brick = [16; 3];
    residency_ingest::convert(&o).unwrap();
    out
}

/// Starts Xvfb on a free display (it picks one and reports it with `-displayfd`).
pub(crate) fn xvfb() -> (Reaped, String) {
    let mut child = Command::new("Xvfb")
        .args(["-displayfd", "1", "-nolisten", "tcp", "-br", "-screen", "0"])
        .arg(format!("{}x{}x24", SCREEN.0, SCREEN.1))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("Xvfb not found: run scripts/setup.sh (Debian package xvfb)");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let n: u32 = line
        .trim()
        .parse()
        .unwrap_or_else(|_| panic!("Xvfb did not report its display: {line:?}"));
    (Reaped(child), format!(":{n}"))
}

/// An X connection to the test's display.
pub(crate) struct X {
    conn: x11rb::rust_connection::RustConnection,
    root: u32,
}

impl X {
    pub(crate) fn open(display: &str) -> Self {
        let (conn, screen) = x11rb::connect(Some(display)).unwrap();
        let root = conn.setup().roots[screen].root;
        Self { conn, root }
    }

    /// [`X::screenshot`] once the screen has not changed for 1 s (at most 6 s after the
    /// call). A presented frame reaches the X server some time after `viewer view` reports
    /// the view settled (Mesa's X11 presentation queues it on a thread of its own): under
    /// load the screen may still show the frame before, or what was there before the window.
    pub(crate) fn still_screenshot(&self) -> Vec<[u8; 3]> {
        const STILL: Duration = Duration::from_secs(1);
        const EVERY: Duration = Duration::from_millis(250);
        let start = Instant::now();
        let mut last = self.screenshot();
        let mut since = Instant::now();
        while since.elapsed() < STILL && start.elapsed() < Duration::from_secs(6) {
            std::thread::sleep(EVERY);
            let now = self.screenshot();
            if now != last {
                last = now;
                since = Instant::now();
            }
        }
        last
    }

    /// The root window's pixels as RGB, row-major.
    pub(crate) fn screenshot(&self) -> Vec<[u8; 3]> {
        let setup = self.conn.setup();
        let (w, h) = SCREEN;
        let image = self
            .conn
            .get_image(ImageFormat::Z_PIXMAP, self.root, 0, 0, w, h, !0)
            .unwrap()
            .reply()
            .unwrap();
        let bpp = setup
            .pixmap_formats
            .iter()
            .find(|f| f.depth == image.depth)
            .map(|f| f.bits_per_pixel)
            .unwrap();
        assert_eq!((image.depth, bpp), (24, 32), "Xvfb runs at depth 24");
        assert_eq!(setup.image_byte_order, ImageOrder::LSB_FIRST);
        let pixels = image
            .data
            .chunks_exact(4)
            .map(|p| [p[2], p[1], p[0]])
            .collect::<Vec<_>>();
        assert_eq!(pixels.len(), w as usize * h as usize);
        pixels
    }

    /// Every top-level window's `_NET_WM_NAME` and `WM_NAME`.
    fn titles(&self) -> Vec<String> {
        let atom = |name: &[u8]| {
            self.conn
                .intern_atom(false, name)
                .unwrap()
                .reply()
                .unwrap()
                .atom
        };
        let (utf8, net_name) = (atom(b"UTF8_STRING"), atom(b"_NET_WM_NAME"));
        let tree = self.conn.query_tree(self.root).unwrap().reply().unwrap();
        let mut titles = Vec::new();
        for win in tree.children {
            for (prop, ty) in [
                (net_name, utf8),
                (AtomEnum::WM_NAME.into(), AtomEnum::STRING.into()),
            ] {
                let r = self
                    .conn
                    .get_property(false, win, prop, ty, 0, 1024)
                    .unwrap()
                    .reply()
                    .unwrap();
                if !r.value.is_empty() {
                    titles.push(String::from_utf8_lossy(&r.value).into_owned());
                }
            }
        }
        titles
    }

    fn fake(&self, kind: u8, detail: u8, x: i16, y: i16) {
        self.conn
            .xtest_fake_input(kind, detail, 0, self.root, x, y, 0)
            .unwrap()
            .check()
            .unwrap();
        self.conn.flush().unwrap();
        std::thread::sleep(Duration::from_millis(30));
    }

    /// Moves the pointer to `(x, y)`, and gives the keyboard focus to the window titled
    /// `viewer: ...` (there is no window manager to do it).
    pub(crate) fn point(&self, x: i16, y: i16) {
        self.fake(MOTION_NOTIFY_EVENT, 0, x, y);
        let tree = self.conn.query_tree(self.root).unwrap().reply().unwrap();
        let window = tree
            .children
            .into_iter()
            .find(|&w| {
                let r = self
                    .conn
                    .get_property(false, w, AtomEnum::WM_NAME, AtomEnum::ANY, 0, 64)
                    .unwrap()
                    .reply()
                    .unwrap();
                r.value.starts_with(b"viewer: ")
            })
            .expect("no viewer window");
        self.conn
            .set_input_focus(InputFocus::PARENT, window, CURRENT_TIME)
            .unwrap()
            .check()
            .unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }

    /// Presses and releases the key that types `ch`.
    pub(crate) fn type_char(&self, ch: char) {
        let setup = self.conn.setup();
        let (min, max) = (setup.min_keycode, setup.max_keycode);
        let map = self
            .conn
            .get_keyboard_mapping(min, max - min + 1)
            .unwrap()
            .reply()
            .unwrap();
        let per = map.keysyms_per_keycode as usize;
        let i = map
            .keysyms
            .chunks(per)
            .position(|syms| syms.first() == Some(&(ch as u32)))
            .unwrap_or_else(|| panic!("no keycode types {ch:?}"));
        let code = min + i as u8;
        self.fake(KEY_PRESS_EVENT, code, 0, 0);
        self.fake(KEY_RELEASE_EVENT, code, 0, 0);
    }

    /// Clicks pointer button `b` (4 is the wheel turned away from the user).
    fn click(&self, b: u8) {
        self.fake(BUTTON_PRESS_EVENT, b, 0, 0);
        self.fake(BUTTON_RELEASE_EVENT, b, 0, 0);
    }

    /// Drags with pointer button `b` from `from` to `to`, in a few motions.
    pub(crate) fn drag(&self, b: u8, from: (i16, i16), to: (i16, i16)) {
        self.fake(MOTION_NOTIFY_EVENT, 0, from.0, from.1);
        self.fake(BUTTON_PRESS_EVENT, b, 0, 0);
        for i in 1..=4 {
            let x = from.0 + (to.0 - from.0) * i / 4;
            let y = from.1 + (to.1 - from.1) * i / 4;
            self.fake(MOTION_NOTIFY_EVENT, 0, x, y);
        }
        self.fake(BUTTON_RELEASE_EVENT, b, 0, 0);
    }
}

fn save_png(pixels: &[[u8; 3]], path: &Path) {
    let (w, h) = SCREEN;
    let img = image::RgbImage::from_raw(w as u32, h as u32, pixels.concat()).unwrap();
    img.save(path).unwrap();
}

/// What a screenshot shows.
#[derive(Debug)]
struct Shot {
    /// Lit pixels outside the window (the root is black).
    outside_lit: usize,
    /// Lit pixels in the window.
    lit: usize,
    /// Saturated pixels below the statistics panel: the rendered volume.
    coloured: usize,
    /// Of those, cyan-, magenta- and yellow-ish ones (the smallest component is red, green,
    /// blue respectively).
    hues: [usize; 3],
    /// White pixels in the panel (its text).
    text: usize,
    /// Pixels of the `x` (red), `y` (green) and `z` (blue) axes' exact colours in the
    /// orientation strip's right half.
    axes: [usize; 3],
    /// White pixels in the orientation strip's left half (the scale bar and its label).
    bar: usize,
}

/// Rows at the window's bottom of the orientation strip (the scale bar and the axes).
const ORIENTATION_ROWS: usize = residency_viewer::interactive::overlay::ORIENTATION_HEIGHT;

/// The axes' colours, as the viewer draws them (`x`, `y`, `z`).
const AXIS_COLOURS: [[u8; 3]; 3] = [[0xff, 0x55, 0x55], [0x55, 0xff, 0x55], [0x55, 0x99, 0xff]];

/// Where the `x` axis (red) is drawn: its pixels' indices in a screenshot.
fn x_axis(pixels: &[[u8; 3]]) -> Vec<usize> {
    (0..pixels.len())
        .filter(|&i| pixels[i] == AXIS_COLOURS[0])
        .collect()
}

/// Rows of the window the statistics panel may cover.
const PANEL_ROWS: usize = 100;

fn analyse(pixels: &[[u8; 3]]) -> Shot {
    let sw = SCREEN.0 as usize;
    let (ww, wh) = (WINDOW.0 as usize, WINDOW.1 as usize);
    let lit = |p: &[u8; 3]| p.iter().any(|&v| v > 24);
    // The channel colours (cyan, magenta, yellow) mix additively; the panel's text is white,
    // grey, or a channel colour lightened by a third.
    let coloured = |p: &[u8; 3]| {
        let (max, min) = (*p.iter().max().unwrap(), *p.iter().min().unwrap());
        max >= 64 && max - min >= 48
    };
    let mut shot = Shot {
        outside_lit: 0,
        lit: 0,
        coloured: 0,
        hues: [0; 3],
        text: 0,
        axes: [0; 3],
        bar: 0,
    };
    for (i, p) in pixels.iter().enumerate() {
        let (x, y) = (i % sw, i / sw);
        if x >= ww || y >= wh {
            shot.outside_lit += lit(p) as usize;
            continue;
        }
        shot.lit += lit(p) as usize;
        if y >= wh - ORIENTATION_ROWS {
            if x >= ww / 2 {
                for (n, colour) in shot.axes.iter_mut().zip(AXIS_COLOURS) {
                    *n += (*p == colour) as usize;
                }
            } else {
                shot.bar += (*p == [0xff; 3]) as usize;
            }
        }
        if y < PANEL_ROWS {
            shot.text += p.iter().all(|&v| v >= 240) as usize;
        } else if coloured(p) {
            shot.coloured += 1;
            for (c, n) in shot.hues.iter_mut().enumerate() {
                *n += (p[c] < p[(c + 1) % 3] && p[c] < p[(c + 2) % 3]) as usize;
            }
        }
    }
    shot
}

#[test]
fn view_shows_a_rendered_frame_and_statistics_under_xvfb_and_follows_input() {
    let start = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let store = store(dir.path());
    let (_xvfb, display) = xvfb();

    let mut cmd = Command::new(env!("CARGO_BIN_EXE_viewer"));
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        cmd.env("XDG_RUNTIME_DIR", "/tmp");
    }
    cmd.env("DISPLAY", &display)
        .env("RUST_LOG", "warn")
        .args(["view", "--store", store.to_str().unwrap()])
        // Nuclei (cyan), membranes (magenta), filaments (yellow), the last made bolder.
        .args(["--camera", "30,-25,1.6", "--tf", "2:2:60:0.5"])
        .args(["--width", &WINDOW.0.to_string()])
        .args(["--height", &WINDOW.1.to_string()])
        // A small image keeps lavapipe quick; it is scaled up to the window.
        .args(["--render-scale", "0.5"])
        .args(["--exit-after-frames", "40", "--exit-delay-ms", "12000"]);
    let (mut viewer, rx, err_thread) = spawn_with_lines(&mut cmd);
    // A summary line comes each time the view settles (converged here); the window then
    // waits 12 s for input before quitting.
    let settle = |what: &str| -> String {
        let line = rx
            .recv_timeout(Duration::from_mins(4))
            .unwrap_or_else(|e| panic!("no summary line {what}: {e}"));
        assert!(
            line.starts_with("view: ") && line.contains("bricks fetched"),
            "{line:?}"
        );
        line
    };
    let x = X::open(&display);
    let shoot = |name: &str| {
        let at = Instant::now();
        let pixels = x.still_screenshot();
        let took = at.elapsed();
        assert!(
            took < Duration::from_secs(7),
            "the screenshot took {took:?}"
        );
        let png = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("view_xvfb_{name}.png"));
        save_png(&pixels, &png);
        let shot = analyse(&pixels);
        eprintln!(
            "{name} at {:.1} s: {} {shot:?}",
            start.elapsed().as_secs_f64(),
            png.display()
        );
        (shot, pixels)
    };

    let line = settle("at start-up");
    assert!(line.ends_with("converged"), "{line:?}");
    let (first, first_pixels) = shoot("start");
    let titles = x.titles();

    // Hide membranes (key 2), then zoom in four wheel steps (half the distance).
    x.point(160, 200);
    x.type_char('2');
    settle("after hiding channel 1");
    let (hidden, hidden_pixels) = shoot("hidden");
    // Orbit: drag right with the left button.
    x.drag(1, (100, 200), (180, 200));
    settle("after orbiting");
    let (orbited, orbited_pixels) = shoot("orbited");
    // Zoom in two wheel steps (distance / √2).
    x.click(4);
    x.click(4);
    settle("after zooming");
    let (zoomed, zoomed_pixels) = shoot("zoomed");
    // Hide the statistics and the orientation (h): the same frame without them.
    x.type_char('h');
    settle("after hiding the statistics");
    let (bare, bare_pixels) = shoot("bare");
    // Switch from DVR to the next mode, maximum intensity projection (m).
    x.type_char('m');
    settle("after switching the mode");
    let (mip, mip_pixels) = shoot("mip");
    // Quit with q, well before the 12 s the settled window would wait.
    let quit = Instant::now();
    x.type_char('q');
    let status = viewer.0.wait().unwrap();
    let quit_took = quit.elapsed();
    let stderr = err_thread.join().unwrap();
    eprintln!("{:.1} s in all", start.elapsed().as_secs_f64());
    assert!(status.success(), "viewer failed: {status}\n{stderr}");

    // The window sits at the screen's origin (no window manager), on the black root.
    let area = (WINDOW.0 * WINDOW.1) as usize;
    assert_eq!(first.outside_lit, 0, "the root outside the window is lit");
    assert!(first.lit >= area / 10, "blank window: {first:?}");
    assert!(
        first.coloured >= area / 50,
        "too few rendered pixels: {first:?}"
    );
    assert!(first.text >= 300, "no statistics panel: {first:?}");
    // The orientation: a scale bar (2 rows over at least 60 pixels, with its label) and the
    // three axes (the z axis is foreshortened, the camera looking along it).
    assert!(first.bar >= 2 * 60 + 40, "no scale bar: {first:?}");
    assert!(first.axes.iter().all(|&n| n >= 8), "no axes: {first:?}");
    for (i, name) in ["cyan", "magenta", "yellow"].iter().enumerate() {
        assert!(first.hues[i] >= 20, "no {name} channel: {first:?}");
    }
    // Without membranes, no magenta is left, and the other channels still show.
    assert!(hidden.hues[1] * 10 < first.hues[1], "{hidden:?}");
    assert!(
        hidden.hues[0] >= 20 && hidden.coloured >= area / 100,
        "{hidden:?}"
    );
    // Orbited, the picture changes (the panel's numbers aside) but still shows the volume.
    let changed = (PANEL_ROWS * SCREEN.0 as usize..hidden_pixels.len())
        .filter(|&i| hidden_pixels[i] != orbited_pixels[i])
        .count();
    assert!(changed >= area / 50, "orbiting changed {changed} pixels");
    assert!(orbited.coloured >= area / 100, "{orbited:?}");
    // ... and the axes turned with the camera.
    assert_ne!(
        x_axis(&orbited_pixels),
        x_axis(&first_pixels),
        "the axes did not turn"
    );
    assert!(orbited.axes.iter().all(|&n| n >= 8), "{orbited:?}");
    // Zoomed in, the volume covers more of the window.
    assert!(
        zoomed.coloured * 4 > orbited.coloured * 5,
        "{zoomed:?} {orbited:?}"
    );
    // Without the statistics and the orientation (h), the rows between them show the same
    // frame, pixel for pixel; the panel's text, the scale bar and the axes are gone.
    let band = |pixels: &[[u8; 3]]| -> Vec<[u8; 3]> {
        let (sw, ww) = (SCREEN.0 as usize, WINDOW.0 as usize);
        (PANEL_ROWS..WINDOW.1 as usize - ORIENTATION_ROWS)
            .flat_map(|y| pixels[y * sw..y * sw + ww].iter().copied())
            .collect()
    };
    let bare_band = band(&bare_pixels);
    assert!(
        bare_band == band(&zoomed_pixels),
        "hiding the statistics changed the frame"
    );
    assert!(
        bare.text * 10 < first.text,
        "the panel still shows: {bare:?}"
    );
    assert!(
        bare.bar < 20 && bare.axes.iter().all(|&n| n < 8),
        "{bare:?}"
    );
    // Another mode (m) draws the same view otherwise, still without the overlays.
    let changed = band(&mip_pixels)
        .iter()
        .zip(&bare_band)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        changed >= area / 50,
        "switching the mode changed {changed} pixels"
    );
    assert!(mip.coloured >= area / 100, "{mip:?}");
    assert!(mip.text * 10 < first.text && mip.bar < 20, "{mip:?}");
    assert!(quit_took < Duration::from_secs(5), "q took {quit_took:?}");

    // The title carries the statistics too.
    let title = titles
        .iter()
        .find(|t| t.starts_with("viewer: "))
        .unwrap_or_else(|| panic!("no viewer window title among {titles:?}"));
    for word in [
        "frame",
        "samples",
        "fetched",
        "substituted",
        "MiB",
        "GPU",
        "converged",
    ] {
        assert!(
            title.contains(word),
            "{word} missing from the title {title:?}"
        );
    }
}

#[test]
fn view_help_lists_the_controls() {
    let out = Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args(["view", "--help"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let help = String::from_utf8(out.stdout).unwrap();
    for s in [
        "left drag",
        "shift + left drag",
        "wheel",
        "ctrl + left drag",
        "1 .. 9",
        "cycle the selected channel's colour",
        "[  ]",
        "{  }",
        // The keys the README names.
        "m                             switch the mode: dvr, mip, iso",
        "h                             hide/show the statistics panel and the orientation",
        "q, Esc                        quit",
        "r                             reset the camera",
        "f                             switch the filter: trilinear, tricubic",
        "Tab, shift + Tab              select the next/previous channel",
        "--exit-after-frames",
        "--server",
        "--store",
    ] {
        assert!(help.contains(s), "{s:?} missing from\n{help}");
    }
}

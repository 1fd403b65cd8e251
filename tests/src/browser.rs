//! A real browser for the scenarios that check a page (net_hmi): Debian's headless
//! Chromium, driven over its DevTools protocol (JSON messages on a WebSocket,
//! <https://chromedevtools.github.io/devtools-protocol/>): navigate, evaluate JavaScript in
//! the page, type text as a user does, take a screenshot.

use base64::Engine;
use serde_json::{Value, json};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

/// Debian's package `chromium` (a scenario's `debian_packages` installs it).
pub const CHROMIUM: &str = "chromium";

/// One headless Chromium with one page; closed when dropped (with every process it
/// started: they share its process group).
pub struct Browser {
    child: Child,
    page: WebSocket<MaybeTlsStream<TcpStream>>,
    next_id: u64,
    profile: PathBuf,
}

impl Browser {
    /// Starts Chromium on about:blank (`--no-sandbox`: the tests run as root) with a
    /// profile of its own, and attaches to its page.
    pub fn launch() -> Result<Browser, String> {
        let profile = std::env::temp_dir().join(format!("warden-chromium-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&profile);
        let mut child = Command::new(CHROMIUM)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--remote-debugging-port=0",
                "--window-size=800,720",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .map_err(|e| format!("cannot start {CHROMIUM}: {e}"))?;
        // "DevTools listening on ws://127.0.0.1:<port>/devtools/browser/<id>" on stderr.
        let mut stderr = BufReader::new(child.stderr.take().expect("piped stderr"));
        let mut port = None;
        let mut line = String::new();
        while port.is_none() && stderr.read_line(&mut line).map_err(|e| e.to_string())? > 0 {
            port = line
                .trim()
                .strip_prefix("DevTools listening on ws://127.0.0.1:")
                .and_then(|rest| rest.split('/').next())
                .and_then(|p| p.parse::<u16>().ok());
            line.clear();
        }
        let Some(port) = port else {
            let _ = child.kill();
            return Err(format!("{CHROMIUM} did not say where its DevTools listen"));
        };
        // Chromium writes more to stderr; it must not block on a full pipe.
        std::thread::spawn(move || std::io::copy(&mut stderr, &mut std::io::sink()));
        let targets = http_json(port, "/json/list")?;
        let url = targets
            .as_array()
            .and_then(|t| t.iter().find(|t| t["type"] == "page"))
            .and_then(|t| t["webSocketDebuggerUrl"].as_str())
            .ok_or_else(|| format!("no page among Chromium's targets: {targets}"))?
            .to_string();
        let (page, _) =
            tungstenite::connect(url.as_str()).map_err(|e| format!("DevTools at {url}: {e}"))?;
        Ok(Browser {
            child,
            page,
            next_id: 1,
            profile,
        })
    }

    /// Calls a DevTools method; its result, or the error it answered.
    pub fn call(&mut self, method: &str, params: Value) -> Result<Value, String> {
        let id = self.next_id;
        self.next_id += 1;
        let request = json!({ "id": id, "method": method, "params": params }).to_string();
        self.page
            .send(Message::text(request))
            .map_err(|e| format!("{method}: {e}"))?;
        loop {
            let message = self.page.read().map_err(|e| format!("{method}: {e}"))?;
            let Message::Text(text) = message else {
                continue;
            };
            let answer: Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
            // Events (no id) and answers to other calls are not this call's.
            if answer["id"] == id {
                if let Some(error) = answer.get("error") {
                    return Err(format!("{method}: {error}"));
                }
                return Ok(answer["result"].clone());
            }
        }
    }

    pub fn navigate(&mut self, url: &str) -> Result<(), String> {
        self.call("Page.navigate", json!({ "url": url })).map(drop)
    }

    /// The value of a JavaScript expression in the page (promises awaited).
    pub fn eval(&mut self, expression: &str) -> Result<Value, String> {
        let r = self.call(
            "Runtime.evaluate",
            json!({ "expression": expression, "returnByValue": true, "awaitPromise": true }),
        )?;
        if let Some(e) = r.get("exceptionDetails") {
            return Err(format!("{expression}: {e}"));
        }
        Ok(r["result"]["value"].clone())
    }

    /// Focuses the element with `id` and types `text` into it as keyboard input.
    pub fn type_into(&mut self, id: &str, text: &str) -> Result<(), String> {
        self.eval(&format!("document.getElementById({id:?}).focus()"))?;
        self.call("Input.insertText", json!({ "text": text }))
            .map(drop)
    }

    /// Clicks the element with `id` with the mouse, at its centre.
    pub fn click(&mut self, id: &str) -> Result<(), String> {
        let at = self.eval(&format!(
            "(r => [r.x + r.width / 2, r.y + r.height / 2])(document.getElementById({id:?}).getBoundingClientRect())"
        ))?;
        let (x, y) = (at[0].as_f64().unwrap_or(0.0), at[1].as_f64().unwrap_or(0.0));
        for kind in ["mousePressed", "mouseReleased"] {
            self.call(
                "Input.dispatchMouseEvent",
                json!({ "type": kind, "x": x, "y": y, "button": "left", "clickCount": 1 }),
            )?;
        }
        Ok(())
    }

    /// The page as a PNG.
    pub fn screenshot(&mut self) -> Result<Vec<u8>, String> {
        let r = self.call("Page.captureScreenshot", json!({ "format": "png" }))?;
        let data = r["data"].as_str().ok_or("no screenshot data")?;
        base64::engine::general_purpose::STANDARD
            .decode(data)
            .map_err(|e| e.to_string())
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.call("Browser.close", json!({}));
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline && matches!(self.child.try_wait(), Ok(None)) {
            std::thread::sleep(Duration::from_millis(100));
        }
        // Whatever is left of it (renderers, zygotes, the crash handler): its process
        // group. The `--` matters: procps-ng 4.0's kill reads `kill -KILL -<pgid>` as
        // `kill(-1, SIGKILL)`, every process the user may signal.
        let _ = Command::new("kill")
            .args(["-KILL", "--", &format!("-{}", self.child.id())])
            .status();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}

/// A JSON document from Chromium's DevTools HTTP endpoint on 127.0.0.1:`port` (it keeps
/// the connection open: the body is as long as its Content-Length says).
fn http_json(port: u16, path: &str) -> Result<Value, String> {
    let get = || -> std::io::Result<String> {
        let mut s = TcpStream::connect(("127.0.0.1", port))?;
        s.set_read_timeout(Some(Duration::from_secs(5)))?;
        // Chromium builds the WebSocket addresses it lists from the Host header.
        write!(s, "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n")?;
        let mut reader = BufReader::new(s);
        let mut length = 0;
        loop {
            let mut line = String::new();
            reader.read_line(&mut line)?;
            let line = line.trim_end();
            if line.is_empty() {
                break;
            }
            if let Some((name, value)) = line.split_once(':')
                && name.eq_ignore_ascii_case("content-length")
            {
                length = value.trim().parse().unwrap_or(0);
            }
        }
        let mut body = vec![0; length];
        reader.read_exact(&mut body)?;
        Ok(String::from_utf8_lossy(&body).into_owned())
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let answer = get();
        if let Ok(body) = &answer
            && let Ok(value) = serde_json::from_str(body)
        {
            return Ok(value);
        }
        if Instant::now() > deadline {
            return Err(format!("no JSON from Chromium's {path}: {answer:?}"));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

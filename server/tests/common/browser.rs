//! Headless Chromium for the web page's tests, driven over its DevTools
//! protocol through `tools/chromium-cdp.py` (a line bridge: one JSON command
//! a line in, one answer a line out; the same pipe transport as
//! `tools/check-report.sh`).

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

/// Set to skip the browser tests on a machine without Chromium (README).
pub const SKIP_VAR: &str = "IMPOSTOR_SKIP_BROWSER_TESTS";

/// One headless Chromium with one page.
pub struct Browser {
    child: Child,
    stdin: Option<ChildStdin>,
    stdout: BufReader<ChildStdout>,
}

impl Browser {
    /// Starts Chromium; `None` when the tests are told to skip it
    /// ([`SKIP_VAR`]); fails with what to install when it cannot start.
    pub fn start() -> Option<Browser> {
        if std::env::var_os(SKIP_VAR).is_some_and(|v| !v.is_empty() && v != "0") {
            eprintln!("{SKIP_VAR} is set: the browser test is skipped");
            return None;
        }
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../tools/chromium-cdp.py");
        let mut child = Command::new("python3")
            .arg(script)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("python3 {script} cannot be started ({e}): install python3")
            });
        let stdout = BufReader::new(child.stdout.take().expect("piped"));
        let stdin = child.stdin.take();
        let mut b = Browser {
            child,
            stdin,
            stdout,
        };
        let ready = b.read();
        assert!(
            ready.get("result").is_some(),
            "headless Chromium did not start ({ready}): install Debian's chromium \
             (tools/install-test-deps.sh does), or set {SKIP_VAR}=1 to skip this test"
        );
        Some(b)
    }

    fn read(&mut self) -> Value {
        let mut line = String::new();
        let n = self.stdout.read_line(&mut line).expect("read the bridge");
        if n == 0 {
            let status = self.child.wait().expect("wait for the bridge");
            panic!(
                "the Chromium bridge exited ({status}): is chromium installed? \
                 (tools/install-test-deps.sh installs it; {SKIP_VAR}=1 skips this test)"
            );
        }
        serde_json::from_str(&line).expect("the bridge answers JSON")
    }

    /// One DevTools command on the page; its result, or its error as `Err`.
    pub fn call(&mut self, method: &str, params: Value) -> Result<Value, Value> {
        let line = json!({"method": method, "params": params}).to_string();
        let stdin = self.stdin.as_mut().expect("open");
        writeln!(stdin, "{line}").expect("write to the bridge");
        stdin.flush().expect("flush");
        let mut answer = self.read();
        match answer.get_mut("result") {
            Some(r) => Ok(r.take()),
            None => Err(answer["error"].take()),
        }
    }

    /// The value of JavaScript `expr` in the page (promises awaited).
    pub fn eval(&mut self, expr: &str) -> Value {
        let r = self
            .call(
                "Runtime.evaluate",
                json!({"expression": expr, "returnByValue": true, "awaitPromise": true}),
            )
            .unwrap_or_else(|e| panic!("{expr}: {e}"));
        if let Some(ex) = r.get("exceptionDetails") {
            panic!("{expr} threw: {ex}\npage problems: {:?}", self.problems());
        }
        r["result"]["value"].clone()
    }

    /// Evaluates `expr` every 100 ms until it is truthy (returns its value),
    /// failing after `limit` with `what` and the page's problems.
    pub fn wait_for(&mut self, expr: &str, limit: Duration, what: &str) -> Value {
        let start = Instant::now();
        loop {
            let v = self.eval(expr);
            let truthy =
                !matches!(&v, Value::Null | Value::Bool(false)) && v != json!("") && v != json!(0);
            if truthy {
                return v;
            }
            if start.elapsed() > limit {
                let body = self.eval("document.body ? document.body.innerText.slice(0, 2000) : ''");
                panic!(
                    "{what}: not within {limit:?} (last value {v})\npage text: {body}\n\
                     page problems: {:?}",
                    self.problems()
                );
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Loads `url` in the page.
    pub fn navigate(&mut self, url: &str) {
        let r = self
            .call("Page.navigate", json!({"url": url}))
            .unwrap_or_else(|e| panic!("navigate to {url}: {e}"));
        assert!(r.get("errorText").is_none(), "navigate to {url}: {r}");
    }

    /// The page's console errors and uncaught exceptions so far.
    pub fn problems(&mut self) -> Vec<String> {
        self.call("bridge.problems", json!({}))
            .ok()
            .and_then(|v| serde_json::from_value(v).ok())
            .unwrap_or_default()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        // End of input: the bridge closes the browser.
        drop(self.stdin.take());
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(20) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

//! Cross-language check helper used by `tests/test_lcm_codec.py`.
//!
//! `lcm-roundtrip decode`  reads an LCM payload (fingerprint + encoding) on stdin, decodes it
//!                         by fingerprint and prints `{"type": "pfnav.x_t", "value": {...}}`.
//! `lcm-roundtrip encode`  reads that JSON form on stdin and writes the payload to stdout.
//! `lcm-roundtrip reencode` reads a payload and writes its re-encoding (must be identical).
//! `lcm-roundtrip fingerprints` prints `type fingerprint` lines for every type.

use std::io::{Read, Write};

use anyhow::{bail, Context, Result};
use lcm_types::AnyMessage;

fn read_stdin() -> Result<Vec<u8>> {
    let mut buf = Vec::new();
    std::io::stdin()
        .read_to_end(&mut buf)
        .context("reading stdin")?;
    Ok(buf)
}

fn main() -> Result<()> {
    let mode = std::env::args().nth(1).unwrap_or_default();
    let mut stdout = std::io::stdout().lock();
    match mode.as_str() {
        "decode" => {
            let msg = AnyMessage::decode(&read_stdin()?).context("decoding the payload")?;
            serde_json::to_writer(&mut stdout, &msg).context("writing JSON")?;
            writeln!(stdout)?;
        }
        "encode" => {
            let msg: AnyMessage =
                serde_json::from_slice(&read_stdin()?).context("parsing the JSON message")?;
            stdout.write_all(&msg.encode().context("encoding")?)?;
        }
        "reencode" => {
            let msg = AnyMessage::decode(&read_stdin()?).context("decoding the payload")?;
            stdout.write_all(&msg.encode().context("encoding")?)?;
        }
        "fingerprints" => {
            for (name, fingerprint) in lcm_types::FINGERPRINTS {
                writeln!(stdout, "{name} {fingerprint:#018x}")?;
            }
        }
        other => bail!("unknown mode '{other}': use decode, encode, reencode or fingerprints"),
    }
    stdout.flush()?;
    Ok(())
}

//! Writing a sequence frame by frame while the next frame is computed.

use super::{FrameOutput, Finished, SequenceWriter};
use crate::error::{Error, Result};

/// Computes and writes the `frames` frames of a sequence through `writer`: `produce(k, out)`
/// fills frame `k`, then `on_frame` runs (an error from it, a stop request, ends the sequence
/// like any failure). With `overlap` the writer runs on its own thread, one frame behind:
/// frame k+1 is computed while frame k is compressed and written, two frame buffers travelling
/// between the threads (no per-frame allocation); without it each frame is written on this
/// thread (to measure the overlap). The files are finished only after the last frame; on an
/// error the writer is dropped and removes its temporary files. Returns what was written and
/// the seconds spent writing.
pub fn write_frames(
    writer: SequenceWriter,
    frames: usize,
    overlap: bool,
    mut produce: impl FnMut(usize, &mut FrameOutput) -> Result<()>,
    mut on_frame: impl FnMut() -> Result<()>,
) -> Result<(Finished, f64)> {
    if !overlap {
        let mut writer = writer;
        let mut out = FrameOutput::default();
        let mut write_s = 0.0;
        for k in 0..frames {
            produce(k, &mut out)?;
            let t0 = std::time::Instant::now();
            writer.write_frame(&out)?;
            write_s += t0.elapsed().as_secs_f64();
            on_frame()?;
        }
        return Ok((writer.finish()?, write_s));
    }
    // A frame's buffers are a few hundred bytes of Vec headers, moved once per frame.
    #[allow(clippy::large_enum_variant)]
    enum Msg {
        Frame(FrameOutput),
        Done,
    }
    let (to_writer, from_main) = std::sync::mpsc::sync_channel::<Msg>(1);
    let (to_main, spare) = std::sync::mpsc::channel::<FrameOutput>();
    to_main.send(FrameOutput::default()).ok();
    to_main.send(FrameOutput::default()).ok();
    std::thread::scope(|scope| {
        let write = scope.spawn(move || -> Result<(Option<Finished>, f64)> {
            let mut write_s = 0.0;
            let mut writer = writer;
            for msg in from_main {
                match msg {
                    Msg::Frame(out) => {
                        let t0 = std::time::Instant::now();
                        writer.write_frame(&out)?;
                        write_s += t0.elapsed().as_secs_f64();
                        let _ = to_main.send(out);
                    }
                    Msg::Done => return writer.finish().map(|f| (Some(f), write_s)),
                }
            }
            Ok((None, write_s))
        });
        let computed = (|| -> Result<()> {
            for k in 0..frames {
                // A buffer comes back once the writer is done with it; none means the writer
                // stopped on an error, reported below.
                let Ok(mut out) = spare.recv() else { return Ok(()) };
                produce(k, &mut out)?;
                if to_writer.send(Msg::Frame(out)).is_err() {
                    return Ok(());
                }
                on_frame()?;
            }
            let _ = to_writer.send(Msg::Done);
            Ok(())
        })();
        drop(to_writer);
        let written = write.join().map_err(|_| Error::Internal("the writer thread panicked".into()))?;
        computed?;
        let (written, write_s) = written?;
        let done = written.ok_or_else(|| Error::Internal("the writer stopped before the last frame".into()))?;
        Ok((done, write_s))
    })
}

//! Reading device buffers back, without blocking where nothing may block: the copy into a
//! mappable buffer is submitted at once, and the returned future resolves when the browser (or,
//! natively, a poll of the device) has mapped it. One readback can carry several buffers, since
//! in a browser each costs milliseconds whatever its size.

use crate::gpu::context::{check, fail, GpuContext, GpuError};
use std::future::Future;

/// The contents of `buffers`, as 32-bit words, once every submitted dispatch has finished:
/// one copy into one mappable buffer, one map. Natively the future blocks on the device when
/// first polled; in a browser it resolves from the event loop, so it must be awaited there. A
/// map that fails (a lost device) is an error, recorded as the context's fault; so is any
/// readback once the context has a fault (its loss, an error no scope caught): the words of a
/// device that failed are not used.
pub fn read_words(
    ctx: &GpuContext,
    buffers: &[&wgpu::Buffer],
) -> impl Future<Output = Result<Vec<Vec<u32>>, GpuError>> + 'static {
    let sizes: Vec<u64> = buffers.iter().map(|b| b.size()).collect();
    let total: u64 = sizes.iter().sum();
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: total.max(4),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    let mut offset = 0;
    for (b, &size) in buffers.iter().zip(&sizes) {
        // Every buffer here holds 32-bit words, so each offset keeps wgpu's 4-byte alignment.
        encoder.copy_buffer_to_buffer(b, 0, &staging, offset, size);
        offset += size;
    }
    let submission = ctx.queue.submit([encoder.finish()]);
    let (tx, rx) = futures_channel::oneshot::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        // The receiver is gone only if the future was dropped: nobody wants the words then.
        let _ = tx.send(r);
    });
    let device = ctx.device.clone();
    let fault = ctx.fault_handle();
    async move {
        let fail = |why: String| fail(&device, &fault, why);
        // This copy's own submission, not the latest: a submission queued behind it (the next
        // steps, submitted ahead) goes on running while its words are read.
        #[cfg(not(target_arch = "wasm32"))]
        crate::gpu::context::wait_for(&device, &fault, Some(submission))?;
        #[cfg(target_arch = "wasm32")]
        let _ = submission;
        let mapped = rx.await.map_err(|_| fail("the readback's map was dropped".into()))?;
        mapped.map_err(|e| fail(format!("a readback did not map: {e}")))?;
        // Mapped, but from a device that failed meanwhile (an error no scope caught, natively
        // also a validation error of a kernel): its words are not used.
        check(&fault)?;
        let data = staging.get_mapped_range(..).map_err(|e| fail(format!("a readback's range: {e}")))?;
        // Copied word by word: a browser's mapped range carries no alignment promise.
        let words: Vec<u32> = data.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect();
        let mut out = Vec::with_capacity(sizes.len());
        let mut at = 0;
        for size in sizes {
            let n = (size / 4) as usize;
            out.push(words[at..at + n].to_vec());
            at += n;
        }
        drop(data);
        staging.unmap();
        Ok(out)
    }
}

/// [`read_words`] of one buffer, blocking (native only); an error if the device failed.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_now(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<u32>, GpuError> {
    let words = pollster::block_on(read_words(ctx, &[buffer]))?;
    // One buffer asked for, one read: `read_words` returns a vector per buffer given.
    Ok(words.into_iter().next().expect("one buffer read"))
}

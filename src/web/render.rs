//! `Renderer`: draws a [`WebView`] into a canvas with wgpu, on WebGPU where the browser has a
//! working adapter and on WebGL2 otherwise (`new_instance_with_webgpu_detection`: a plain
//! instance picks WebGPU whenever `navigator.gpu` exists, even with no adapter behind it).
//!
//! The canvas holds the lattice as a square, and under it, for the fields, the colour bar. The
//! page reads the layout back ([`Renderer::layout`]) to place the bar's labels and to map the
//! pointer to lattice sites, so the geometry lives in one place.

use std::sync::{Arc, Mutex};

use bytemuck::Zeroable;
use wasm_bindgen::prelude::*;

use super::binding::js_err;
use web_sys::HtmlCanvasElement;
use wgpu::util::DeviceExt;

use super::view::{FieldKind, Segment, View};

const COMMON_WGSL: &str = include_str!("../../shaders/common.wgsl");
const FIELD_WGSL: &str = include_str!("../../shaders/field.wgsl");
const SEGMENTS_WGSL: &str = include_str!("../../shaders/segments.wgsl");

/// Page background (sRGB), also the canvas clear colour.
const BACKGROUND: [f64; 3] = [0.059, 0.067, 0.082];
/// Colour bar height and gap above it, in CSS pixels.
const BAR_CSS: f32 = 12.0;
const GAP_CSS: f32 = 8.0;

/// `shaders/common.wgsl`'s `Uniforms`, field for field.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    /// L, device pixels per CSS pixel, side of the drawn lattice in device pixels, unused.
    lattice: [f32; 4],
    /// Colour range of the field (min, max), unused ×2.
    range: [f32; 4],
    /// Booleans (0/1): a field is shown, its colormap is the signed one, the surface wants linear
    /// values, the painted substrate is tinted.
    flags: [u32; 4],
}

/// One frame's drawing data, handed from the simulation (here or in a worker) to a renderer.
#[wasm_bindgen]
pub struct WebView(pub(crate) View);

#[wasm_bindgen]
impl WebView {
    /// A view from its parts, as [`WebView::tissue`], [`WebView::field`] and
    /// [`WebView::segments`] give them (to draw a frame built elsewhere, e.g. in a worker).
    #[wasm_bindgen(constructor)]
    pub fn new(
        l: usize,
        kind: FieldKind,
        tissue: &[f32],
        field: &[f32],
        segments: &[f32],
        range: &[f32],
    ) -> Result<WebView, JsError> {
        let seg_floats = std::mem::size_of::<Segment>() / 4;
        if tissue.len() != 4 * l * l
            || field.len() != 4 * l * l
            || !segments.len().is_multiple_of(seg_floats)
            || range.len() != 2
        {
            return Err(JsError::new("WebView: parts of the wrong sizes"));
        }
        Ok(WebView(View {
            l,
            kind,
            tissue: bytemuck::cast_slice(tissue).to_vec(),
            field: bytemuck::cast_slice(field).to_vec(),
            segments: bytemuck::cast_slice(segments).to_vec(),
            range: (range[0], range[1]),
        }))
    }

    pub fn l(&self) -> usize {
        self.0.l
    }

    pub fn kind(&self) -> FieldKind {
        self.0.kind
    }

    /// (key₁, φ₁, key₂, φ₂) per site.
    pub fn tissue(&self) -> Vec<f32> {
        bytemuck::cast_slice(&self.0.tissue).to_vec()
    }

    /// (value, substrate multiplier, 0, 0) per site.
    pub fn field(&self) -> Vec<f32> {
        bytemuck::cast_slice(&self.0.field).to_vec()
    }

    /// Twelve floats per segment.
    pub fn segments(&self) -> Vec<f32> {
        bytemuck::cast_slice(&self.0.segments).to_vec()
    }

    /// Colour range of the field, [min, max].
    pub fn range(&self) -> Vec<f32> {
        vec![self.0.range.0, self.0.range.1]
    }

    /// One RGBA pixel per site, row 0 at the top: the view as the page's Canvas 2D renderer
    /// draws it, where there is neither WebGPU nor WebGL2 (`raster::site_colours`).
    pub fn rgba(&self, substrate: bool) -> Vec<u8> {
        super::raster::site_colours(&self.0, substrate)
    }
}

/// The colour bar of a field, `n` RGBA pixels from its minimum to its maximum (the Canvas 2D
/// renderer's; the wgpu renderer draws it in `shaders/field.wgsl`).
#[wasm_bindgen(js_name = barColours)]
pub fn bar_colours(kind: FieldKind, n: usize) -> Vec<u8> {
    super::raster::bar_colours(kind, n)
}

/// Where the lattice square and the colour bar go on a canvas of `width × height` device
/// pixels, as [`Renderer::layout`] gives it. The Canvas 2D renderer places its drawing with it,
/// so that every renderer shares one geometry.
#[wasm_bindgen(js_name = canvasLayout)]
pub fn canvas_layout(width: u32, height: u32, dpr: f32, with_bar: bool) -> Layout {
    Layout::of(width.max(1), height.max(1), dpr, with_bar)
}

/// Where things are on the canvas, in device pixels (the page maps pointers and places the
/// colour bar's labels with it).
#[wasm_bindgen]
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// The lattice square's left edge.
    pub x: f32,
    /// The lattice square's top edge.
    pub y: f32,
    /// The lattice square's side.
    pub side: f32,
    /// The colour bar's top (same left and width as the square).
    pub bar_y: f32,
    /// The colour bar's height.
    pub bar_h: f32,
}

impl Layout {
    fn of(width: u32, height: u32, dpr: f32, with_bar: bool) -> Layout {
        let (w, h) = (width as f32, height as f32);
        let reserve = if with_bar { (BAR_CSS + GAP_CSS) * dpr } else { 0.0 };
        let side = w.min(h - reserve).max(1.0).floor();
        let x = ((w - side) / 2.0).floor();
        let y = ((h - reserve - side) / 2.0).max(0.0).floor();
        Layout { x, y, side, bar_y: y + side + GAP_CSS * dpr, bar_h: BAR_CSS * dpr }
    }
}

/// The page's drawing of a [`WebView`] on its canvas, wgpu on WebGPU or WebGL2.
#[wasm_bindgen]
pub struct Renderer {
    canvas: HtmlCanvasElement,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    backend: String,
    /// The surface encodes to sRGB itself: the shaders must write linear values.
    linear_out: bool,
    field_pipeline: wgpu::RenderPipeline,
    bar_pipeline: wgpu::RenderPipeline,
    segment_pipeline: wgpu::RenderPipeline,
    layout_bgl: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    /// Lattice side, textures and bind group (rebuilt when the side changes).
    l: usize,
    textures: Option<(wgpu::Texture, wgpu::Texture, wgpu::BindGroup)>,
    segments: wgpu::Buffer,
    segment_capacity: usize,
    layout: Layout,
    /// Validation errors, reported asynchronously by wgpu; `draw` returns them.
    errors: Arc<Mutex<Vec<String>>>,
    /// Why the device was lost, once it is (driver reset, sleep, a crash of the browser's GPU
    /// process, or `destroy_device`): the page polls it and makes a new renderer.
    lost: Arc<Mutex<Option<String>>>,
}

#[wasm_bindgen]
impl Renderer {
    /// Finds a GPU for the canvas (WebGPU if `webgpu` allows it and the browser has an adapter,
    /// else WebGL2) and builds the pipelines. Rejects with a message a person can act on when
    /// the browser offers neither. The page asks without WebGPU when it falls back after WebGPU
    /// devices were lost again and again.
    pub async fn create(canvas: HtmlCanvasElement, webgpu: bool) -> Result<Renderer, JsError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = if webgpu { wgpu::Backends::BROWSER_WEBGPU | wgpu::Backends::GL } else { wgpu::Backends::GL };
        let instance = wgpu::util::new_instance_with_webgpu_detection(desc).await;
        let surface = instance
            .create_surface(wgpu::SurfaceTarget::Canvas(canvas.clone()))
            .map_err(|e| JsError::new(&format!("This browser offers neither WebGPU nor WebGL2 ({e}).")))?;
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::default(),
                force_fallback_adapter: false,
                compatible_surface: Some(&surface),
                apply_limit_buckets: false,
            })
            .await
            .map_err(|e| JsError::new(&format!("No GPU adapter for WebGPU or WebGL2 ({e}).")))?;
        let info = adapter.get_info();
        let backend = format!("{:?}", info.backend).replace("BrowserWebGpu", "WebGPU").replace("Gl", "WebGL2");
        // The smallest limits that WebGL2 guarantees are all this renderer needs.
        let required_limits = wgpu::Limits::downlevel_webgl2_defaults().using_resolution(adapter.limits());
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("monolayer"),
                required_features: wgpu::Features::empty(),
                required_limits,
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::default(),
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(js_err)?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device
            .on_uncaptured_error(Arc::new(move |e: wgpu::Error| sink.lock().unwrap().push(format!("GPU error: {e}"))));
        let lost = Arc::new(Mutex::new(None));
        let sink = lost.clone();
        device.set_device_lost_callback(move |reason, msg| {
            sink.lock().unwrap().get_or_insert(format!("the GPU device was lost ({reason:?}: {msg})"));
        });

        let (w, h) = (canvas.width().max(1), canvas.height().max(1));
        let config = surface
            .get_default_config(&adapter, w, h)
            .ok_or_else(|| JsError::new("The canvas surface is not supported by this GPU adapter."))?;
        surface.configure(&device, &config);
        let linear_out = config.format.is_srgb();

        let layout_bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lattice"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                texture_entry(1),
                texture_entry(2),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("lattice"),
            bind_group_layouts: &[Some(&layout_bgl)],
            immediate_size: 0,
        });
        let module = |name: &str, body: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl([COMMON_WGSL, body].concat().into()),
            })
        };
        let field_module = module("field.wgsl", FIELD_WGSL);
        let segment_module = module("segments.wgsl", SEGMENTS_WGSL);
        let format = config.format;
        let pipeline =
            |label: &str, m: &wgpu::ShaderModule, vs: &str, fs: &str, buffers: &[Option<wgpu::VertexBufferLayout>]| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(label),
                    layout: Some(&pipeline_layout),
                    vertex: wgpu::VertexState {
                        module: m,
                        entry_point: Some(vs),
                        compilation_options: Default::default(),
                        buffers,
                    },
                    primitive: wgpu::PrimitiveState::default(),
                    depth_stencil: None,
                    multisample: wgpu::MultisampleState::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: m,
                        entry_point: Some(fs),
                        compilation_options: Default::default(),
                        targets: &[Some(wgpu::ColorTargetState {
                            format,
                            blend: Some(wgpu::BlendState::ALPHA_BLENDING),
                            write_mask: wgpu::ColorWrites::ALL,
                        })],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
        let field_pipeline = pipeline("field", &field_module, "vs_full", "fs_field", &[]);
        let bar_pipeline = pipeline("colour bar", &field_module, "vs_full", "fs_bar", &[]);
        const SEGMENT_ATTRIBUTES: [wgpu::VertexAttribute; 4] =
            wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x2, 2 => Float32x4, 3 => Float32];
        let segment_pipeline = pipeline(
            "segments",
            &segment_module,
            "vs_seg",
            "fs_seg",
            &[Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<Segment>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &SEGMENT_ATTRIBUTES,
            })],
        );
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("uniforms"),
            contents: bytemuck::bytes_of(&Uniforms::zeroed()),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let segment_capacity = 1024;
        let segments = segment_buffer(&device, segment_capacity);
        Ok(Renderer {
            canvas,
            surface,
            device,
            queue,
            config,
            backend,
            linear_out,
            field_pipeline,
            bar_pipeline,
            segment_pipeline,
            layout_bgl,
            uniforms,
            l: 0,
            textures: None,
            segments,
            segment_capacity,
            layout: Layout::of(w, h, 1.0, false),
            errors,
            lost,
        })
    }

    /// "WebGPU" or "WebGL2", and the adapter's surface format.
    pub fn backend(&self) -> String {
        format!("{} ({:?})", self.backend, self.config.format)
    }

    /// GPU errors reported since the last call (validation), one per line.
    pub fn take_errors(&self) -> Option<String> {
        let mut e = self.errors.lock().unwrap();
        (!e.is_empty()).then(|| e.drain(..).collect::<Vec<_>>().join("\n"))
    }

    /// Why the device was lost, or nothing while it works. A lost device draws nothing more;
    /// the page then makes a new renderer (new adapter, new device).
    pub fn lost(&self) -> Option<String> {
        self.lost.lock().unwrap().clone()
    }

    /// Destroys the device, as a driver reset would (the browser tests' forced loss).
    pub fn destroy_device(&self) {
        self.device.destroy();
    }

    /// Where the lattice square and the colour bar are, in device pixels, as last drawn.
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// Draws `view`; `dpr` is the page's devicePixelRatio (the bar is in CSS pixels),
    /// `substrate` tints the painted substrate. The canvas's backing size is the page's to set
    /// (it tracks the window); the surface follows it here.
    pub fn draw(&mut self, view: &WebView, dpr: f32, substrate: bool) -> Result<(), JsError> {
        let view = &view.0;
        let kind = view.kind;
        if self.lost().is_some() {
            return Ok(()); // nothing draws on a lost device: the page is making a new renderer
        }
        let (w, h) = (self.canvas.width().max(1), self.canvas.height().max(1));
        if (w, h) != (self.config.width, self.config.height) {
            self.config.width = w;
            self.config.height = h;
            self.surface.configure(&self.device, &self.config);
        }
        let with_bar = kind.shows_field();
        self.layout = Layout::of(w, h, dpr, with_bar);
        if view.l != self.l || self.textures.is_none() {
            self.textures = Some(self.lattice_textures(view.l));
            self.l = view.l;
        }
        let (tissue_tex, field_tex, bind_group) = self.textures.as_ref().expect("built above");
        for (tex, data) in [(tissue_tex, &view.tissue), (field_tex, &view.field)] {
            self.queue.write_texture(
                tex.as_image_copy(),
                bytemuck::cast_slice(data),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(16 * view.l as u32),
                    rows_per_image: None,
                },
                tex.size(),
            );
        }
        let u = Uniforms {
            lattice: [view.l as f32, dpr, self.layout.side, 0.0],
            range: [view.range.0, view.range.1, 0.0, 0.0],
            flags: [kind.shows_field(), kind.is_signed(), self.linear_out, substrate].map(u32::from),
        };
        self.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
        if view.segments.len() > self.segment_capacity {
            self.segment_capacity = view.segments.len().next_power_of_two();
            self.segments = segment_buffer(&self.device, self.segment_capacity);
        }
        self.queue.write_buffer(&self.segments, 0, bytemuck::cast_slice(&view.segments));

        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            // A frame that cannot be had now is skipped; the next one reconfigures.
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.device, &self.config);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(JsError::new(&self.take_errors().unwrap_or_else(|| "surface validation error".into())))
            }
        };
        let target = frame.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let bg = if self.linear_out { BACKGROUND.map(srgb_to_linear) } else { BACKGROUND };
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("frame"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color { r: bg[0], g: bg[1], b: bg[2], a: 1.0 }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let g = self.layout;
            pass.set_bind_group(0, bind_group, &[]);
            pass.set_viewport(g.x, g.y, g.side, g.side, 0.0, 1.0);
            pass.set_pipeline(&self.field_pipeline);
            pass.draw(0..3, 0..1);
            if !view.segments.is_empty() {
                pass.set_pipeline(&self.segment_pipeline);
                pass.set_vertex_buffer(0, self.segments.slice(..));
                pass.draw(0..6, 0..view.segments.len() as u32);
            }
            if with_bar && g.bar_y + g.bar_h <= h as f32 {
                pass.set_viewport(g.x, g.bar_y, g.side, g.bar_h, 0.0, 1.0);
                pass.set_pipeline(&self.bar_pipeline);
                pass.draw(0..3, 0..1);
            }
        }
        self.queue.submit([encoder.finish()]);
        self.queue.present(frame);
        match self.take_errors() {
            Some(e) => Err(JsError::new(&e)),
            None => Ok(()),
        }
    }
}

impl Renderer {
    fn lattice_textures(&self, l: usize) -> (wgpu::Texture, wgpu::Texture, wgpu::BindGroup) {
        let make = |label| {
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: l as u32, height: l as u32, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        };
        let (tissue, field) = (make("tissue"), make("field"));
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lattice"),
            layout: &self.layout_bgl,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.uniforms.as_entire_binding() },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&tissue.create_view(&Default::default())),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&field.create_view(&Default::default())),
                },
            ],
        });
        (tissue, field, bind_group)
    }
}

/// f32 textures are not filterable: the shader reads them with `textureLoad`.
fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

fn segment_buffer(device: &wgpu::Device, capacity: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("segments"),
        size: (capacity * std::mem::size_of::<Segment>()) as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        libm::pow((c + 0.055) / 1.055, 2.4)
    }
}

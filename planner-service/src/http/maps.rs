//! Floor-plan routes: list, upload (ROS YAML + image, or a picture with its scale), preview,
//! metadata, versions and the occupancy image.
//!
//! Uploads go through map-store's importers with their image limits: the parts are staged in
//! a private folder under `<data-dir>/uploads/`, imported and validated completely, and only
//! then stored, so a bad upload stores nothing. A YAML's `image` entry is rewritten to the
//! staged image, so an upload can never make the service read another file of the host.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::multipart::{Multipart, MultipartRejection};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path as UrlPath, Query, Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::Json;
use futures::StreamExt;
use map_store::import::{import_file, Imported};
use map_store::store::content_hash;
use map_store::{ImportLimits, OccupancyGrid, PictureOptions, FREE, OCCUPIED, UNKNOWN};
use protocol::{MapMeta, MapName, Pose2D};
use serde::Deserialize;

use super::error::ApiError;
use super::ranges;
use super::state::AppState;

/// The most of an oversized body that is read and thrown away before answering 413.
const DRAIN_MAX_BYTES: u64 = 256 << 20;

/// Answers 413 to a body whose declared length exceeds `limit`, before any parsing.
///
/// The body is read and discarded first (up to [`DRAIN_MAX_BYTES`]): a client that is still
/// sending when the server answers and closes the connection sees a reset instead of the
/// answer, and a browser would show "network error" rather than the reason.
pub async fn refuse_oversized(limit: u64, req: Request, next: Next) -> Response {
    let declared = req
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    let Some(len) = declared.filter(|&n| n > limit) else {
        return next.run(req).await;
    };
    if len <= DRAIN_MAX_BYTES {
        let mut body = req.into_body().into_data_stream();
        while let Some(Ok(_)) = body.next().await {}
    }
    ApiError::too_large(format!(
        "upload of {len} bytes exceeds http.max_upload_bytes = {limit}"
    ))
    .into_response()
}

/// `GET /api/v1/maps`: the latest version of each name.
pub async fn list(State(state): State<AppState>) -> Result<Json<Vec<MapMeta>>, ApiError> {
    let maps = state.maps.clone();
    let all = tokio::task::spawn_blocking(move || maps.list()).await??;
    // `list` sorts newest first within a name, so the first of each name is its latest.
    let mut latest: Vec<MapMeta> = Vec::new();
    for m in all {
        if latest.last().is_none_or(|l| l.name != m.name) {
            latest.push(m);
        }
    }
    Ok(Json(latest))
}

/// `GET /api/v1/maps/{name}`.
pub async fn meta(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
) -> Result<Json<MapMeta>, ApiError> {
    let name = MapName::new(name)?;
    let maps = state.maps.clone();
    Ok(Json(
        tokio::task::spawn_blocking(move || maps.meta(&name, None)).await??,
    ))
}

/// `GET /api/v1/maps/{name}/versions`: oldest first; 404 for an unknown name.
pub async fn versions(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
) -> Result<Json<Vec<MapMeta>>, ApiError> {
    let name = MapName::new(name)?;
    let maps = state.maps.clone();
    let lookup = name.clone();
    let v = tokio::task::spawn_blocking(move || maps.versions(&lookup)).await??;
    if v.is_empty() {
        return Err(ApiError::not_found(format!("no map named {name}")));
    }
    Ok(Json(v))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageQuery {
    version: Option<u32>,
    /// Accepted (and ignored here) so a protected dashboard can put its token in image URLs.
    #[serde(rename = "access_token")]
    _access_token: Option<String>,
}

/// `GET /api/v1/maps/{name}/image[?version=N]`: the occupancy grid as PNG, rendered once per
/// map version ([`super::images::ImageCache`]); `304` when `If-None-Match` names its id.
pub async fn image(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
    query: Result<Query<ImageQuery>, QueryRejection>,
    headers: axum::http::HeaderMap,
) -> Result<Response, ApiError> {
    let Query(q) = query?;
    let name = MapName::new(name)?;
    if q.version == Some(0) {
        return Err(ApiError::bad_request(
            "invalid version = 0: versions start at 1",
        ));
    }
    let maps = state.maps.clone();
    let meta = tokio::task::spawn_blocking(move || maps.meta(&name, q.version)).await??;
    // The id is content addressed: the same id always has the same picture.
    let etag = HeaderValue::from_str(&format!("\"{}\"", meta.id))
        .map_err(|e| ApiError::internal(format!("map id is no header value: {e}")))?;
    if let Some(resp) = super::images::not_modified(headers.get(header::IF_NONE_MATCH), &etag) {
        return Ok(resp);
    }
    let png = match state.map_images.get(meta.id.as_str()) {
        Some(png) => png,
        None => {
            let maps = state.maps.clone();
            let id = meta.id.clone();
            let png: Arc<[u8]> = tokio::task::spawn_blocking(move || {
                let stored = maps.get_by_id(&id)?;
                Ok::<_, ApiError>(grid_png(&stored.grid)?.into())
            })
            .await??;
            state.map_images.insert(meta.id.as_str(), Arc::clone(&png));
            png
        }
    };
    let mut resp = png_response(&meta_geometry(&meta), png.to_vec());
    resp.headers_mut().insert(header::ETAG, etag);
    Ok(resp)
}

/// `POST /api/v1/maps`: `201` with the new version, `200` with the existing one when the same
/// content is already stored under the name.
pub async fn upload(
    State(state): State<AppState>,
    multipart: Result<Multipart, MultipartRejection>,
) -> Result<Response, ApiError> {
    let parts = UploadParts::read(multipart?).await?;
    let _room = state.decodes.admit(parts.decode_cost_bytes()).await?;
    let name_text = parts
        .name
        .clone()
        .ok_or_else(|| ApiError::bad_request("missing part `name` (the map name)"))?;
    let name = MapName::new(name_text)?;
    let maps = state.maps.clone();
    let data_dir = state.data_dir.clone();
    let limits = state.http.import_limits;
    let (meta, created) = tokio::task::spawn_blocking(move || {
        let imported = parts.import(&data_dir, &limits)?;
        let hash = content_hash(&imported.grid);
        let existed = maps.versions(&name)?.iter().any(|m| m.content_hash == hash);
        let meta = maps.put(&name, &imported.grid, &imported.source)?;
        Ok::<_, ApiError>((meta, !existed))
    })
    .await??;
    let status = if created {
        tracing::info!(map = %meta.name, version = meta.version, id = %meta.id, "map stored");
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((status, Json(meta)).into_response())
}

/// `POST /api/v1/maps/preview`: the PNG an upload would store; stores nothing.
pub async fn preview(
    State(state): State<AppState>,
    multipart: Result<Multipart, MultipartRejection>,
) -> Result<Response, ApiError> {
    let parts = UploadParts::read(multipart?).await?;
    if let Some(n) = &parts.name {
        MapName::new(n.clone())?;
    }
    let _room = state.decodes.admit(parts.decode_cost_bytes()).await?;
    let data_dir = state.data_dir.clone();
    let limits = state.http.import_limits;
    let (geometry, png) = tokio::task::spawn_blocking(move || {
        let imported = parts.import(&data_dir, &limits)?;
        let g = &imported.grid;
        let geometry = (g.width_cells(), g.height_cells(), g.resolution_m());
        Ok::<_, ApiError>((geometry, grid_png(g)?))
    })
    .await??;
    Ok(png_response(&geometry, png))
}

fn meta_geometry(m: &MapMeta) -> (u32, u32, f64) {
    (m.width_cells, m.height_cells, m.resolution_m)
}

fn png_response(geometry: &(u32, u32, f64), png: Vec<u8>) -> Response {
    let (w, h, res) = *geometry;
    let mut resp = ([(header::CONTENT_TYPE, "image/png")], png).into_response();
    let headers = resp.headers_mut();
    for (k, v) in [
        ("x-map-width", w.to_string()),
        ("x-map-height", h.to_string()),
        ("x-map-resolution-m", res.to_string()),
    ] {
        if let Ok(v) = HeaderValue::from_str(&v) {
            headers.insert(k, v);
        }
    }
    resp
}

/// Grey value of a cell: free white, occupied black, unknown grey, occupancy percentages in
/// between as shades.
fn shade(cell: u8) -> u8 {
    match cell {
        FREE => 255,
        OCCUPIED => 0,
        UNKNOWN => 128,
        // 1..=99 (scale-mode maps); anything else is not a ROS value and shows as unknown.
        v if v < OCCUPIED => {
            let s = (100 - u16::from(v)) * 255 / 100;
            u8::try_from(s).unwrap_or(u8::MAX)
        }
        _ => 128,
    }
}

/// The grid as an 8-bit grey PNG, top row = largest y (grid row 0 is at the bottom).
///
/// # Errors
/// [`ApiError::internal`] if encoding fails.
pub fn grid_png(grid: &OccupancyGrid) -> Result<Vec<u8>, ApiError> {
    use image::ImageEncoder;
    let (w, h) = (grid.width_cells(), grid.height_cells());
    let width = w as usize;
    let cells = grid.cells();
    let mut pixels = Vec::with_capacity(cells.len());
    for row in (0..h as usize).rev() {
        pixels.extend(
            cells[row * width..(row + 1) * width]
                .iter()
                .map(|&c| shade(c)),
        );
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(&pixels, w, h, image::ExtendedColorType::L8)
    .map_err(|e| ApiError::internal(format!("cannot encode PNG: {e}")))?;
    Ok(out)
}

/// A file part: its client-side file name and bytes.
#[derive(Debug)]
struct FilePart {
    file_name: String,
    bytes: Bytes,
}

/// The parts of an upload or preview request.
#[derive(Debug, Default)]
struct UploadParts {
    name: Option<String>,
    yaml: Option<FilePart>,
    image: Option<FilePart>,
    picture: Option<FilePart>,
    resolution_m: Option<String>,
    origin_x_m: Option<String>,
    origin_y_m: Option<String>,
}

impl UploadParts {
    async fn read(mut multipart: Multipart) -> Result<Self, ApiError> {
        let mut parts = Self::default();
        while let Some(field) = multipart.next_field().await? {
            let part = field.name().unwrap_or_default().to_string();
            let file_name = field.file_name().unwrap_or(&part).to_string();
            let bytes = field.bytes().await?;
            let text = || {
                String::from_utf8(bytes.to_vec())
                    .map(|s| s.trim().to_string())
                    .map_err(|_| ApiError::bad_request(format!("part `{part}` is not UTF-8 text")))
            };
            let file = || FilePart {
                file_name: file_name.clone(),
                bytes: bytes.clone(),
            };
            let slot_filled = match part.as_str() {
                "name" => parts.name.replace(text()?).is_some(),
                "resolution_m" => parts.resolution_m.replace(text()?).is_some(),
                "origin_x_m" => parts.origin_x_m.replace(text()?).is_some(),
                "origin_y_m" => parts.origin_y_m.replace(text()?).is_some(),
                "yaml" => parts.yaml.replace(file()).is_some(),
                "image" => parts.image.replace(file()).is_some(),
                "picture" => parts.picture.replace(file()).is_some(),
                other => {
                    return Err(ApiError::bad_request(format!(
                        "unknown part `{other}`: expected name, yaml + image, or picture + resolution_m [+ origin_x_m, origin_y_m]"
                    )))
                }
            };
            if slot_filled {
                return Err(ApiError::bad_request(format!("part `{part}` given twice")));
            }
        }
        Ok(parts)
    }

    /// Memory decoding the upload's image takes at the peak, from its header; 0 when there is
    /// no image or its header cannot be read (the import then refuses it before decoding).
    fn decode_cost_bytes(&self) -> u64 {
        let Some(file) = self.image.as_ref().or(self.picture.as_ref()) else {
            return 0;
        };
        map_store::ros::decode_cost_bytes(&file.bytes, Path::new(&file.file_name)).unwrap_or(0)
    }

    /// Stages the files, imports them with map-store's importer, checks the map's physical
    /// ranges ([`ranges::map_geometry`]) and returns the grid; the staging folder is removed
    /// whatever happens. Errors name the upload's parts, never the staging folder.
    fn import(&self, data_dir: &Path, limits: &ImportLimits) -> Result<Imported, ApiError> {
        let staging = Staging::create(data_dir)?;
        let imported = self
            .import_staged(&staging, limits)
            .map_err(|e| staging.hide(e, |f| self.part_label(f)))?;
        ranges::map_geometry(&imported.grid)?;
        Ok(imported)
    }

    /// What the client calls a staged file: `part \`image\` (plan.pgm)`.
    fn part_label(&self, staged_file: &str) -> String {
        let (part, file) = if staged_file == "map.yaml" {
            ("yaml", self.yaml.as_ref())
        } else if staged_file.starts_with("map.") {
            ("image", self.image.as_ref())
        } else if staged_file.starts_with("picture.") {
            ("picture", self.picture.as_ref())
        } else {
            return "the upload".to_string();
        };
        match file {
            Some(f) => format!("part `{part}` ({})", f.file_name),
            None => format!("part `{part}`"),
        }
    }

    fn import_staged(
        &self,
        staging: &Staging,
        limits: &ImportLimits,
    ) -> Result<Imported, ApiError> {
        let (mut imported, uploaded_name) = match (&self.yaml, &self.image, &self.picture) {
            (Some(yaml), Some(image), None) => {
                let picture_part = [
                    ("resolution_m", &self.resolution_m),
                    ("origin_x_m", &self.origin_x_m),
                    ("origin_y_m", &self.origin_y_m),
                ]
                .into_iter()
                .find_map(|(part, v)| v.as_ref().map(|_| part));
                if let Some(part) = picture_part {
                    return Err(ApiError::bad_request(format!(
                        "part `{part}` belongs to a picture upload; a ROS map gives it in its YAML"
                    )));
                }
                let yaml_path = staging.write_ros(yaml, image)?;
                let imported = import_file(&yaml_path, None, limits)?;
                (
                    imported,
                    format!("{} + {}", yaml.file_name, image.file_name),
                )
            }
            (None, None, Some(picture)) => {
                let opts = self.picture_options()?;
                let path = staging.write(
                    &format!("picture.{}", image_ext(&picture.file_name)),
                    &picture.bytes,
                )?;
                let imported = import_file(&path, Some(&opts), limits)?;
                (imported, picture.file_name.clone())
            }
            (None, None, None) => return Err(ApiError::bad_request(
                "no map given: send parts `yaml` + `image` (ROS map) or `picture` + `resolution_m`",
            )),
            (Some(_), None, _) => {
                return Err(ApiError::bad_request(
                    "part `yaml` needs the part `image` (the map image it names)",
                ))
            }
            (None, Some(_), _) => {
                return Err(ApiError::bad_request(
                    "part `image` needs the part `yaml` (a picture goes in part `picture`)",
                ))
            }
            (Some(_), Some(_), Some(_)) => {
                return Err(ApiError::bad_request(
                    "give either `yaml` + `image` or `picture`, not both",
                ))
            }
        };
        imported.source.path = Some(format!("upload:{uploaded_name}"));
        Ok(imported)
    }

    fn picture_options(&self) -> Result<PictureOptions, ApiError> {
        let number = |field: &str, v: Option<&String>| -> Result<Option<f64>, ApiError> {
            v.map(|s| {
                s.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        ApiError::bad_request(format!(
                            "invalid {field} = {s:?}: expected a finite number"
                        ))
                    })
            })
            .transpose()
        };
        let resolution_m =
            number("resolution_m", self.resolution_m.as_ref())?.ok_or_else(|| {
                ApiError::bad_request(
                    "missing part `resolution_m` (metres per pixel of the picture)",
                )
            })?;
        ranges::resolution("resolution_m", resolution_m)?;
        let origin_x_m = number("origin_x_m", self.origin_x_m.as_ref())?.unwrap_or(0.0);
        let origin_y_m = number("origin_y_m", self.origin_y_m.as_ref())?.unwrap_or(0.0);
        ranges::coordinate("origin_x_m", origin_x_m)?;
        ranges::coordinate("origin_y_m", origin_y_m)?;
        let mut opts = PictureOptions::new(resolution_m);
        opts.origin = Pose2D::new(origin_x_m, origin_y_m, 0.0);
        Ok(opts)
    }
}

/// A lower-case extension of letters and digits from a client file name, else `img`; the
/// importer sniffs the format from the bytes, the extension only has to not look like YAML.
fn image_ext(file_name: &str) -> String {
    let ext = Path::new(file_name)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .filter(|e| e.len() <= 5 && e.chars().all(|c| c.is_ascii_alphanumeric()))
        .unwrap_or_default();
    if ext.is_empty() || ext == "yaml" || ext == "yml" {
        "img".to_string()
    } else {
        ext
    }
}

/// A private folder for one upload, removed on drop.
struct Staging {
    dir: PathBuf,
}

static STAGING_SEQ: AtomicU64 = AtomicU64::new(0);

impl Staging {
    fn create(data_dir: &Path) -> Result<Self, ApiError> {
        let seq = STAGING_SEQ.fetch_add(1, Ordering::Relaxed);
        let dir = data_dir
            .join("uploads")
            .join(format!("{}-{seq}", std::process::id()));
        // A folder left by a crashed earlier process with the same pid is stale: start clean.
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| {
            tracing::error!(dir = %dir.display(), error = %e, "cannot create an upload staging folder");
            ApiError::internal(format!("cannot create the upload staging folder: {e}"))
        })?;
        Ok(Self { dir })
    }

    fn write(&self, file: &str, bytes: &[u8]) -> Result<PathBuf, ApiError> {
        let path = self.dir.join(file);
        std::fs::write(&path, bytes).map_err(|e| {
            tracing::error!(path = %path.display(), error = %e, "cannot stage an upload");
            ApiError::internal(format!("cannot stage the upload's {file}: {e}"))
        })?;
        Ok(path)
    }

    /// Writes the image as `map.<ext>` and the YAML with its `image` entry pointing there.
    fn write_ros(&self, yaml: &FilePart, image: &FilePart) -> Result<PathBuf, ApiError> {
        let text = std::str::from_utf8(&yaml.bytes).map_err(|_| {
            ApiError::bad_request(format!(
                "part `yaml` ({}) is not UTF-8 text",
                yaml.file_name
            ))
        })?;
        let mut doc: serde_yaml::Value = serde_yaml::from_str(text).map_err(|e| {
            ApiError::bad_request(format!(
                "cannot parse part `yaml` ({}): {e}",
                yaml.file_name
            ))
        })?;
        let map = doc.as_mapping_mut().ok_or_else(|| {
            ApiError::bad_request(format!(
                "part `yaml` ({}) is not a mapping of map_server keys",
                yaml.file_name
            ))
        })?;
        let named = map
            .get("image")
            .and_then(serde_yaml::Value::as_str)
            .ok_or_else(|| {
                ApiError::bad_request(format!(
                    "part `yaml` ({}): missing field `image` (the image file name)",
                    yaml.file_name
                ))
            })?;
        let named_file = Path::new(named)
            .file_name()
            .and_then(|f| f.to_str())
            .unwrap_or(named);
        if named_file != image.file_name {
            tracing::debug!(named, uploaded = %image.file_name, "YAML names another image file than the upload's");
        }
        let image_file = format!("map.{}", image_ext(&image.file_name));
        map.insert("image".into(), image_file.clone().into());
        let rewritten = serde_yaml::to_string(&doc)
            .map_err(|e| ApiError::internal(format!("cannot rewrite map YAML: {e}")))?;
        self.write(&image_file, &image.bytes)?;
        self.write("map.yaml", rewritten.as_bytes())
    }
}

impl Staging {
    /// The error with the staging folder's files named by what the client uploaded (`part
    /// \`image\` (plan.pgm)`) and the folder itself (server path, process id) left out.
    fn hide(&self, mut e: ApiError, label: impl Fn(&str) -> String) -> ApiError {
        let dir = self.dir.display().to_string();
        if !e.reason.contains(&dir) {
            return e;
        }
        let mut files: Vec<(String, String)> = std::fs::read_dir(&self.dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|f| f.file_name().into_string().ok())
            .map(|f| (self.dir.join(&f).display().to_string(), label(&f)))
            .collect();
        // Longest first, so a file's path is replaced before the folder's.
        files.sort_by_key(|(path, _)| std::cmp::Reverse(path.len()));
        for (path, part) in files {
            e.reason = e.reason.replace(&path, &part);
        }
        e.reason = e.reason.replace(&dir, "the upload");
        e
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if let Err(e) = std::fs::remove_dir_all(&self.dir) {
            tracing::warn!(dir = %self.dir.display(), error = %e, "cannot remove staging folder");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_puts_grid_row_zero_at_the_bottom() {
        // 2 × 2: bottom row free, occupied; top row unknown, 50 %.
        let grid = OccupancyGrid::new(2, 2, 0.1, Pose2D::default(), vec![0, 100, 255, 50]).unwrap();
        let png = grid_png(&grid).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_luma8();
        assert_eq!(img.dimensions(), (2, 2));
        assert_eq!(img.get_pixel(0, 0).0, [128]);
        assert_eq!(img.get_pixel(1, 0).0, [127]);
        assert_eq!(img.get_pixel(0, 1).0, [255]);
        assert_eq!(img.get_pixel(1, 1).0, [0]);
    }

    #[test]
    fn extensions_are_sanitized() {
        assert_eq!(image_ext("plan.PNG"), "png");
        assert_eq!(image_ext("evil.yaml"), "img");
        assert_eq!(image_ext("noext"), "img");
        assert_eq!(image_ext("x.p/g"), "img");
    }
}

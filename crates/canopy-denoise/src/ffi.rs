//! The few functions of OIDN 2's C API a denoise takes (`OpenImageDenoise/oidn.h`), loaded
//! from the library, and a device that releases itself. All `unsafe` of the crate is here.

use crate::DenoiseError;
use libloading::Library;
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::Path;

type DeviceHandle = *mut c_void;
type FilterHandle = *mut c_void;

/// `OIDN_DEVICE_TYPE_CPU`.
const DEVICE_TYPE_CPU: c_int = 1;
/// `OIDN_FORMAT_FLOAT3`.
const FORMAT_FLOAT3: c_int = 3;
/// `OIDN_ERROR_NONE`.
const ERROR_NONE: c_int = 0;

/// The functions, copied out of the library that `_library` keeps loaded.
pub(crate) struct Api {
    new_device: unsafe extern "C" fn(c_int) -> DeviceHandle,
    set_device_int: unsafe extern "C" fn(DeviceHandle, *const c_char, c_int),
    commit_device: unsafe extern "C" fn(DeviceHandle),
    release_device: unsafe extern "C" fn(DeviceHandle),
    get_device_error: unsafe extern "C" fn(DeviceHandle, *mut *const c_char) -> c_int,
    new_filter: unsafe extern "C" fn(DeviceHandle, *const c_char) -> FilterHandle,
    set_shared_filter_image: unsafe extern "C" fn(
        FilterHandle,
        *const c_char,
        *mut c_void,
        c_int,
        usize,
        usize,
        usize,
        usize,
        usize,
    ),
    set_filter_bool: unsafe extern "C" fn(FilterHandle, *const c_char, bool),
    commit_filter: unsafe extern "C" fn(FilterHandle),
    execute_filter: unsafe extern "C" fn(FilterHandle),
    release_filter: unsafe extern "C" fn(FilterHandle),
    _library: Library,
}

impl Api {
    /// Loads the library at `path` (a bare file name: found by the system's loader) and
    /// its functions.
    pub(crate) fn open(path: &Path) -> Result<Api, String> {
        // SAFETY: loading runs the library's initialisers; OIDN's only set up its own
        // state. The path is one the user or canopy's installer put OIDN at.
        let library = unsafe { Library::new(path.as_os_str()) }.map_err(|e| e.to_string())?;
        macro_rules! function {
            ($name:literal) => {{
                // SAFETY: the type is the function's in oidn.h (OIDN 2.x); the pointer
                // stays valid while `_library` keeps the library loaded.
                let symbol = unsafe { library.get(concat!($name, "\0").as_bytes()) }
                    .map_err(|e| format!("{}: {e}", $name))?;
                *symbol
            }};
        }
        Ok(Api {
            new_device: function!("oidnNewDevice"),
            set_device_int: function!("oidnSetDeviceInt"),
            commit_device: function!("oidnCommitDevice"),
            release_device: function!("oidnReleaseDevice"),
            get_device_error: function!("oidnGetDeviceError"),
            new_filter: function!("oidnNewFilter"),
            set_shared_filter_image: function!("oidnSetSharedFilterImage"),
            set_filter_bool: function!("oidnSetFilterBool"),
            commit_filter: function!("oidnCommitFilter"),
            execute_filter: function!("oidnExecuteFilter"),
            release_filter: function!("oidnReleaseFilter"),
            _library: library,
        })
    }
}

/// An OIDN CPU device, released when dropped.
pub(crate) struct Device<'a> {
    api: &'a Api,
    handle: DeviceHandle,
}

impl<'a> Device<'a> {
    pub(crate) fn new(api: &'a Api, threads: Option<usize>) -> Result<Self, DenoiseError> {
        // SAFETY: a call with a valid device type; a null handle is checked.
        let handle = unsafe { (api.new_device)(DEVICE_TYPE_CPU) };
        if handle.is_null() {
            return Err(DenoiseError::Failed(
                "no CPU device (is libOpenImageDenoise_device_cpu beside the library?)".into(),
            ));
        }
        let device = Device { api, handle };
        if let Some(threads) = threads {
            let threads = c_int::try_from(threads).unwrap_or(c_int::MAX);
            // SAFETY: a live device and a NUL-terminated parameter name.
            unsafe { (api.set_device_int)(handle, c"numThreads".as_ptr(), threads) };
        }
        // SAFETY: a live device.
        unsafe { (api.commit_device)(handle) };
        device.check()?;
        Ok(device)
    }

    /// The device's pending error, if any.
    fn check(&self) -> Result<(), DenoiseError> {
        let mut message: *const c_char = std::ptr::null();
        // SAFETY: a live device; OIDN points `message` at a string it owns (or leaves
        // it null), valid until the next call on the device.
        let code = unsafe { (self.api.get_device_error)(self.handle, &mut message) };
        if code == ERROR_NONE {
            return Ok(());
        }
        let text = match message.is_null() {
            true => format!("error {code}"),
            // SAFETY: non-null and NUL-terminated, per the API.
            false => unsafe { CStr::from_ptr(message) }
                .to_string_lossy()
                .into_owned(),
        };
        Err(DenoiseError::Failed(text))
    }

    /// Runs OIDN's `RT` filter on `inputs` (name and RGB floats, each width x height
    /// pixels, checked by the caller) and returns its output. `clean_aux`: the albedo
    /// and normal among the inputs are free of noise.
    pub(crate) fn filter(
        &self,
        width: usize,
        height: usize,
        inputs: &[(&str, &[f32])],
        clean_aux: bool,
    ) -> Result<Vec<f32>, DenoiseError> {
        let mut output = vec![0.0f32; width * height * 3];
        let api = self.api;
        // SAFETY: a live device and a NUL-terminated filter type.
        let filter = unsafe { (api.new_filter)(self.handle, c"RT".as_ptr()) };
        self.check()?;
        if filter.is_null() {
            return Err(DenoiseError::Failed("no RT filter".into()));
        }
        let result = (|| {
            let names: Vec<CString> = inputs
                .iter()
                .map(|(name, _)| CString::new(*name).expect("no NUL in an image name"))
                .collect();
            for ((_, pixels), name) in inputs.iter().zip(&names) {
                // SAFETY: OIDN reads width * height packed RGB floats from the pointer
                // (the caller checked the length) during execute, while `inputs` lives;
                // it never writes through an input.
                unsafe {
                    (api.set_shared_filter_image)(
                        filter,
                        name.as_ptr(),
                        pixels.as_ptr() as *mut c_void,
                        FORMAT_FLOAT3,
                        width,
                        height,
                        0,
                        0,
                        0,
                    )
                };
            }
            // SAFETY: as above, for the output it writes during execute.
            unsafe {
                (api.set_shared_filter_image)(
                    filter,
                    c"output".as_ptr(),
                    output.as_mut_ptr() as *mut c_void,
                    FORMAT_FLOAT3,
                    width,
                    height,
                    0,
                    0,
                    0,
                );
                // A render's radiance is high dynamic range; an albedo or normal alone
                // (prefiltered) is not, and takes no `hdr` flag.
                if inputs[0].0 == "color" {
                    (api.set_filter_bool)(filter, c"hdr".as_ptr(), true);
                    (api.set_filter_bool)(filter, c"cleanAux".as_ptr(), clean_aux);
                }
                (api.commit_filter)(filter);
            }
            self.check()?;
            // SAFETY: a committed filter whose images are all alive.
            unsafe { (api.execute_filter)(filter) };
            self.check()
        })();
        // SAFETY: the filter is released once, after its last use.
        unsafe { (api.release_filter)(filter) };
        result.map(|()| output)
    }
}

impl Drop for Device<'_> {
    fn drop(&mut self) {
        // SAFETY: the device is released once, after its filters.
        unsafe { (self.api.release_device)(self.handle) };
    }
}

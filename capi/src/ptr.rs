//! Turning the caller's raw pointers into references and slices, with every check that can be
//! made on a pointer: null, alignment, and a byte length that fits in `isize`.

use std::ffi::{CStr, c_char};

use crate::status::{Failure, null};

/// `len` elements of `T` at `ptr`; a null `ptr` is fine when `len` is zero.
///
/// # Safety
/// A non-null `ptr` must point to `len` initialised elements that stay valid and unmodified
/// for `'a`.
pub(crate) unsafe fn slice<'a, T>(
    ptr: *const T,
    len: usize,
    name: &str,
) -> Result<&'a [T], Failure> {
    check(ptr, len, name)?;
    if len == 0 {
        return Ok(&[]);
    }
    // SAFETY: non-null, aligned, and the byte length fits in isize (checked above); the caller
    // guarantees `len` valid elements for 'a.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// `len` writable elements of `T` at `ptr`; a null `ptr` is fine when `len` is zero.
///
/// # Safety
/// A non-null `ptr` must point to `len` elements writable for `'a` and not aliased.
pub(crate) unsafe fn slice_mut<'a, T>(
    ptr: *mut T,
    len: usize,
    name: &str,
) -> Result<&'a mut [T], Failure> {
    check(ptr, len, name)?;
    if len == 0 {
        return Ok(&mut []);
    }
    // SAFETY: as `slice`, plus the caller's promise of exclusive access.
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
}

/// The object behind a handle or struct pointer.
///
/// # Safety
/// A non-null `ptr` must point to a live `T` for `'a`.
pub(crate) unsafe fn object<'a, T>(ptr: *const T, name: &str) -> Result<&'a T, Failure> {
    check(ptr, 1, name)?;
    // SAFETY: non-null and aligned (checked); the caller guarantees a live T.
    Ok(unsafe { &*ptr })
}

/// The object behind a mutable handle.
///
/// # Safety
/// A non-null `ptr` must point to a live `T` that nothing else accesses for `'a`.
pub(crate) unsafe fn object_mut<'a, T>(ptr: *mut T, name: &str) -> Result<&'a mut T, Failure> {
    check(ptr, 1, name)?;
    // SAFETY: non-null and aligned (checked); the caller guarantees exclusive access.
    Ok(unsafe { &mut *ptr })
}

/// A NUL-terminated UTF-8 string.
///
/// # Safety
/// A non-null `ptr` must point to a NUL-terminated string valid for `'a`.
pub(crate) unsafe fn utf8<'a>(ptr: *const c_char, name: &str) -> Result<&'a str, Failure> {
    if ptr.is_null() {
        return Err(null(name));
    }
    // SAFETY: non-null; the caller guarantees a NUL-terminated string.
    let c = unsafe { CStr::from_ptr(ptr) };
    c.to_str()
        .map_err(|e| Failure::invalid(format!("`{name}` is not UTF-8: {e}")))
}

/// Writes `value` through an out-pointer.
///
/// # Safety
/// A non-null `ptr` must be valid for a write of `T`.
pub(crate) unsafe fn write<T>(ptr: *mut T, value: T, name: &str) -> Result<(), Failure> {
    check(ptr, 1, name)?;
    // SAFETY: non-null and aligned (checked); the caller guarantees it is writable.
    unsafe { ptr.write(value) };
    Ok(())
}

fn check<T>(ptr: *const T, len: usize, name: &str) -> Result<(), Failure> {
    if len == 0 {
        return Ok(());
    }
    if ptr.is_null() {
        return Err(null(name));
    }
    if !ptr.is_aligned() {
        return Err(Failure::invalid(format!(
            "`{name}` is not aligned to {} bytes",
            align_of::<T>()
        )));
    }
    let fits = len
        .checked_mul(size_of::<T>())
        .is_some_and(|b| isize::try_from(b).is_ok());
    if !fits {
        return Err(Failure::invalid(format!(
            "`{name}`: {len} elements exceed the address space"
        )));
    }
    Ok(())
}

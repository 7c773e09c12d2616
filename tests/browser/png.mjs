// A small PNG decoder for the browser tests: 8-bit grey, grey+alpha, RGB or RGBA,
// non-interlaced (what `ptmkit relight` and Chromium's toDataURL write). Returns
// {width, height, rgb: Uint8Array of width * height * 3}.
import {inflateSync} from 'node:zlib';

export function decodePng(buf) {
  const sig = [137, 80, 78, 71, 13, 10, 26, 10];
  for (let i = 0; i < 8; ++i) {
    if (buf[i] !== sig[i]) throw new Error('not a PNG');
  }
  let pos = 8, width = 0, height = 0, depth = 0, type = 0, interlace = 0;
  const idat = [];
  while (pos < buf.length) {
    const len = buf.readUInt32BE(pos);
    const name = buf.toString('latin1', pos + 4, pos + 8);
    const data = buf.subarray(pos + 8, pos + 8 + len);
    if (name === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      depth = data[8];
      type = data[9];
      interlace = data[12];
    } else if (name === 'IDAT') {
      idat.push(data);
    } else if (name === 'IEND') {
      break;
    }
    pos += 12 + len;
  }
  const channels = {0: 1, 2: 3, 4: 2, 6: 4}[type];
  if (depth !== 8 || !channels || interlace !== 0) {
    throw new Error(`PNG: depth ${depth}, colour type ${type}, interlace ${interlace} not handled`);
  }
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const px = new Uint8Array(stride * height);
  for (let y = 0; y < height; ++y) {
    const f = raw[y * (stride + 1)];
    const src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    const out = px.subarray(y * stride, (y + 1) * stride);
    const up = y > 0 ? px.subarray((y - 1) * stride, y * stride) : null;
    for (let i = 0; i < stride; ++i) {
      const a = i >= channels ? out[i - channels] : 0;
      const b = up ? up[i] : 0;
      const c = up && i >= channels ? up[i - channels] : 0;
      let v = src[i];
      if (f === 1) v += a;
      else if (f === 2) v += b;
      else if (f === 3) v += (a + b) >> 1;
      else if (f === 4) {
        const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
        v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      } else if (f !== 0) throw new Error('PNG: bad filter ' + f);
      out[i] = v & 255;
    }
  }
  const rgb = new Uint8Array(width * height * 3);
  for (let i = 0; i < width * height; ++i) {
    for (let k = 0; k < 3; ++k) {
      rgb[3 * i + k] = channels >= 3 ? px[i * channels + k] : px[i * channels];
    }
  }
  return {width, height, rgb};
}

// Mean and max absolute difference (grey levels) over R, G, B of two images of one size.
export function diff(a, b) {
  if (a.width !== b.width || a.height !== b.height) {
    throw new Error(`size ${a.width}x${a.height} vs ${b.width}x${b.height}`);
  }
  let sum = 0, max = 0;
  for (let i = 0; i < a.rgb.length; ++i) {
    const d = Math.abs(a.rgb[i] - b.rgb[i]);
    sum += d;
    if (d > max) max = d;
  }
  return {mean: sum / a.rgb.length, max};
}

export function flipVertical(img) {
  const {width, height, rgb} = img;
  const out = new Uint8Array(rgb.length);
  for (let y = 0; y < height; ++y) {
    out.set(rgb.subarray((height - 1 - y) * width * 3, (height - y) * width * 3), y * width * 3);
  }
  return {width, height, rgb: out};
}

export function flipHorizontal(img) {
  const {width, height, rgb} = img;
  const out = new Uint8Array(rgb.length);
  for (let y = 0; y < height; ++y) {
    for (let x = 0; x < width; ++x) {
      for (let k = 0; k < 3; ++k) {
        out[(y * width + x) * 3 + k] = rgb[(y * width + (width - 1 - x)) * 3 + k];
      }
    }
  }
  return {width, height, rgb: out};
}

export function crop(img, x0, y0, w, h) {
  const out = new Uint8Array(w * h * 3);
  for (let y = 0; y < h; ++y) {
    out.set(img.rgb.subarray(((y0 + y) * img.width + x0) * 3, ((y0 + y) * img.width + x0 + w) * 3),
      y * w * 3);
  }
  return {width: w, height: h, rgb: out};
}

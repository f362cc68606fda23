// The PSNR of one PNG against another over a mask's white pixels (eroded by
// one pixel), all at the first image's size: a function run inside a
// Chromium page (puppeteer's page.evaluate), which decodes the PNGs.
async function comparePixels(urls) {
  const images = await Promise.all(urls.map(async (url) => {
    const image = new Image();
    image.src = url;
    await image.decode();
    return image;
  }));
  const width = images[0].naturalWidth, height = images[0].naturalHeight;
  const pixels = images.map((image) => {
    const canvas = new OffscreenCanvas(width, height);
    const context = canvas.getContext('2d');
    context.imageSmoothingQuality = 'high';
    context.drawImage(image, 0, 0, width, height);
    return context.getImageData(0, 0, width, height).data;
  });
  const [ours, theirs, mask] = pixels;
  const inside = (x, y) => x >= 0 && y >= 0 && x < width && y < height && mask[4 * (y * width + x)] > 128;
  let sum = 0, count = 0;
  for (let y = 0; y < height; ++y)
    for (let x = 0; x < width; ++x) {
      let kept = true;
      for (let dy = -1; dy <= 1 && kept; ++dy)
        for (let dx = -1; dx <= 1 && kept; ++dx) kept = inside(x + dx, y + dy);
      if (!kept) continue;
      for (let c = 0; c < 3; ++c) sum += (ours[4 * (y * width + x) + c] - theirs[4 * (y * width + x) + c]) ** 2;
      ++count;
    }
  return { psnr: 10 * Math.log10(255 * 255 / Math.max(sum / (3 * Math.max(count, 1)), 1e-9)), count };
}

module.exports = { comparePixels };
